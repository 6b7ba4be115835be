"""The example plugin in plugins/tactbench-example: installed, listed, and it encodes."""

from __future__ import annotations

import importlib.metadata
import json
import os

import numpy as np
import pytest
from click.testing import CliRunner

from tactbench.cli import cli
from tactbench.plugins import load_registry


@pytest.fixture(scope="module")
def installed():
    try:
        importlib.metadata.distribution("tactbench-example")
    except importlib.metadata.PackageNotFoundError:
        if os.environ.get("CI"):
            pytest.fail("tactbench-example is not installed; the README's install command "
                        "installs it with 'pip install -e plugins/tactbench-example'")
        pytest.skip("tactbench-example not installed (pip install -e plugins/tactbench-example)")


def test_listed_with_its_distribution(installed):
    doc = json.loads(CliRunner().invoke(cli, ["list", "--json"]).stdout)
    comp = next(c for c in doc["components"] if c["name"] == "contact-events")
    assert comp["plugin"] == "example" and comp["distribution"] == "tactbench-example"
    assert comp["available"] is True


def test_it_encodes_contact_onsets_and_releases(installed):
    encoder = load_registry().build("encoder", "contact-events:threshold=0.2")
    seq = np.zeros((3, 2, 2), np.float32)
    seq[0, 0, 0] = 0.9          # touched at frame 0 …
    seq[1, 0, 0] = 0.1          # … released at frame 1
    seq[1:, 1, 1] = 0.5         # touched from frame 1 on
    out = encoder.encode(seq)
    assert out.shape == (3, 3, 2, 2) and out.dtype == np.float32
    np.testing.assert_array_equal(out[:, 0], seq)
    assert out[0, 1, 0, 0] == 1 and out[1, 1, 0, 0] == 0           # contact mask
    assert out[0, 2, 0, 0] == 1.0 and out[1, 2, 0, 0] == 0.0        # onset, release
    assert out[1, 2, 1, 1] == 1.0 and out[2, 2, 1, 1] == 0.5        # onset, held
    with pytest.raises(ValueError, match="threshold"):
        load_registry().build("encoder", "contact-events:threshold=1.5")
    with pytest.raises(ValueError, match="non-finite"):
        encoder.encode(np.full((2, 2, 2), np.nan, np.float32))


from tactbench.testing import conformance_cases, run_check  # noqa: E402


@pytest.mark.parametrize("encoder, check", conformance_cases(
    ["contact-events", "contact-events:threshold=0.2"]))
def test_conformance_suite(installed, encoder, check):
    """The plugin passes the same conformance suite as the built-in encoders."""
    run_check(encoder, check)

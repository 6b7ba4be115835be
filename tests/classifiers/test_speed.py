"""The work-saving paths of the torch classifiers (issue 21): channels-last encoding,
shared frame features across overlapping windows, and gradient checkpointing of the
backbone. Each must do the same arithmetic as the plain path where it claims to, and
be a named option where it changes the sampling."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from tactbench.classifiers.batching import FrameBank, share_frames, window_runs
from tactbench.classifiers.efficientnet import EfficientNetB0
from tactbench.classifiers.nets import SequenceNet, SharedWindows, SmallCNN, checkpointed
from tactbench.classifiers.training import epoch_order
from tactbench.classifiers.conformance import tiny_windows
from tactbench.data.windows import Windows, test_windows, training_windows
from tactbench.errors import InputError
from tactbench.plugins import load_registry

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _seqs(n=6, t_range=(2, 11), shape=(2, 9, 11), seed=0):
    rng = np.random.default_rng(seed)
    seqs = [rng.random((int(rng.integers(*t_range)), *shape), dtype=np.float32)
            for _ in range(n)]
    return seqs, np.arange(n) % 3


def _step(net, x, y, seed=5):
    """One SGD step from ``net``'s weights; returns the loss and the state after."""
    net.train()
    torch.manual_seed(seed)  # dropout and stochastic depth draw the same
    opt = torch.optim.SGD(net.parameters(), lr=0.1, momentum=0.9)
    loss = F.cross_entropy(net(x), y)
    loss.backward()
    opt.step()
    return loss.item(), {k: v.detach().clone() for k, v in net.state_dict().items()}


# ----------------------------------------------------------------------- channels last


@pytest.mark.parametrize("channels", [1, 2])
def test_channels_last_is_the_nchw_arithmetic_to_float_rounding(channels):
    torch.manual_seed(0)
    net = SequenceNet(SmallCNN(channels, 8, 3), frame_shape=(channels, 20, 20), n_classes=3,
                      hidden=8, fc=16, dropout=0.0, input_size=16)
    assert net.channels_last  # the default path
    nchw = copy.deepcopy(net)
    nchw.channels_last = False
    x, y = torch.rand(6, 4, channels, 20, 20), torch.tensor([0, 1, 2, 0, 1, 2])
    loss_a, state_a = _step(net, x, y)
    loss_b, state_b = _step(nchw, x, y)
    assert loss_a == pytest.approx(loss_b, rel=1e-5)
    for k in state_a:
        torch.testing.assert_close(state_a[k], state_b[k], rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("channels", [1, 3])
def test_frames_reach_the_encoder_channels_last_one_channel_included(channels):
    """One channel is NCHW and channels-last at once; unmarked, torch keeps NCHW for the
    whole network. The frames must reach the first convolution with channels-last
    strides, and its output must be channels-last."""
    net = SequenceNet(SmallCNN(channels, 8, 2), frame_shape=(channels, 20, 20), n_classes=3,
                      hidden=8, fc=16, dropout=0.0, input_size=16)
    seen = {}
    first = net.encoder.body[0]
    first.register_forward_hook(lambda m, inp, out: seen.update(inp=inp[0], out=out))
    net.eval()
    with torch.no_grad():
        net(torch.rand(2, 3, channels, 20, 20))
    assert seen["inp"].stride()[1] == 1  # channel stride of channels-last
    assert seen["out"].is_contiguous(memory_format=torch.channels_last)
    assert not seen["out"].is_contiguous()  # 8 channels: the layouts differ


def test_pooling_before_relu_is_the_same_network_bit_for_bit():
    """SmallCNN pools before its ReLU (cheaper); conv → BN → ReLU → pool, the textbook
    order it had, gives the same loss and the same weights after a step, exactly."""
    torch.manual_seed(0)
    net = SequenceNet(SmallCNN(3, 8, 3), frame_shape=(3, 20, 20), n_classes=3, hidden=8,
                      fc=16, dropout=0.0, input_size=15)  # odd sizes: ceil-mode pooling
    assert [type(m).__name__ for m in net.encoder.body[:4]] == [
        "Conv2d", "BatchNorm2d", "MaxPool2d", "ReLU"]
    textbook = copy.deepcopy(net)
    mods = list(textbook.encoder.body)
    for i in range(0, len(mods), 4):
        mods[i + 2], mods[i + 3] = mods[i + 3], mods[i + 2]
    textbook.encoder.body = torch.nn.Sequential(*mods)
    SmallCNN.pool_before_relu = False  # the benchmark's "before" builds the same order
    try:
        assert [type(m).__name__ for m in SmallCNN(3, 8, 3).body[:4]] == [
            "Conv2d", "BatchNorm2d", "ReLU", "MaxPool2d"]
    finally:
        SmallCNN.pool_before_relu = True
    x, y = torch.randn(6, 4, 3, 20, 20), torch.tensor([0, 1, 2, 0, 1, 2])
    loss_a, state_a = _step(net, x, y)
    loss_b, state_b = _step(textbook, x, y)
    assert loss_a == loss_b
    assert state_a.keys() == state_b.keys()  # saved weights load either way
    for k in state_a:
        assert torch.equal(state_a[k], state_b[k]), k


# ----------------------------------------------------------------------- checkpointing


@pytest.mark.parametrize("segments", [1, 3, 100])
def test_a_checkpointed_step_equals_the_plain_step(segments):
    """Same loss, same weights after an SGD step, same BatchNorm running statistics
    (updated once, not again by the recomputation), stochastic depth replayed."""
    torch.manual_seed(0)
    net = SequenceNet(EfficientNetB0(3, drop_path=0.2), frame_shape=(3, 36, 36),
                      n_classes=4, hidden=8, fc=16, dropout=0.3, input_size=32)
    ckpt = copy.deepcopy(net)
    ckpt.checkpoint_segments = segments
    x, y = torch.rand(4, 2, 3, 36, 36), torch.tensor([0, 1, 2, 3])
    loss_a, state_a = _step(net, x, y)
    loss_b, state_b = _step(ckpt, x, y)
    assert loss_a == pytest.approx(loss_b, rel=1e-6)
    bn = [k for k in state_a if "running_" in k or "num_batches" in k]
    assert bn and all(torch.equal(state_a[k], state_b[k]) for k in bn)
    for k in state_a:
        torch.testing.assert_close(state_a[k], state_b[k], rtol=1e-5, atol=1e-6)


def test_checkpointing_only_in_training_and_from_the_size_it_is_set_for():
    reg = load_registry()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        big = reg.build("classifier", "cnn-lstm", input_size=224)._build_net(
            (3, 40, 40), 3, pretrained=False)
        small = reg.build("classifier", "cnn-lstm", input_size=32)._build_net(
            (3, 40, 40), 3, pretrained=False)
    assert big.checkpoint_segments > 0 and small.checkpoint_segments == 0
    # in eval mode the checkpointed net is the plain forward
    big.eval()
    plain = copy.deepcopy(big)
    plain.checkpoint_segments = 0
    x = torch.rand(2, 2, 3, 40, 40)
    with torch.no_grad():
        torch.testing.assert_close(big(x), plain(x))


def test_checkpointed_encoder_matches_for_a_plain_cnn():
    torch.manual_seed(1)
    cnn = SmallCNN(1, 4, 3)
    x = torch.rand(5, 1, 16, 16, requires_grad=True)
    out = checkpointed(cnn, x, 2)
    assert out.shape == (5, cnn.out_features)
    out.sum().backward()
    grad = x.grad.clone()
    x.grad = None
    cnn2 = copy.deepcopy(cnn)
    torch.manual_seed(1)
    cnn2(x).sum().backward()
    torch.testing.assert_close(grad, x.grad)


# ----------------------------------------------------------------------- shared features


@pytest.mark.parametrize("run", [None, 2, 5])
def test_window_runs_group_overlapping_windows_of_one_sequence(run):
    seqs, labels = _seqs()
    win = training_windows(seqs, labels, 3)
    runs = window_runs(win, run)
    k = 3 if run is None else run  # runs of L by default
    assert runs.shape == (len(win),)
    sizes = []
    for r in np.unique(runs):
        members = np.flatnonzero(runs == r)
        assert len(set(win.seq_index[members])) == 1
        assert len(members) <= k
        assert win.starts[members].max() - win.starts[members].min() <= k - 1
        sizes.append(len(members))
    assert max(sizes) == k  # the sequences are long enough for full runs


def test_grouped_epoch_order_keeps_runs_together_and_covers_every_window():
    groups = np.repeat(np.arange(7), [3, 3, 1, 3, 2, 3, 3])
    order = epoch_order(np.random.default_rng(0), len(groups), 0, groups)
    assert sorted(order) == list(range(len(groups)))
    # each group appears as one contiguous stretch
    seen = groups[order]
    changes = np.flatnonzero(np.diff(seen)) + 1
    assert len(changes) + 1 == 7
    cut = epoch_order(np.random.default_rng(0), len(groups), 30, groups)
    assert len(cut) == 30 and set(cut) == set(range(len(groups)))
    # without groups the order is today's: a plain permutation from the same draws
    assert np.array_equal(epoch_order(np.random.default_rng(4), 18, 0),
                          np.random.default_rng(4).permutation(18))


def test_shared_batch_encodes_each_distinct_frame_once_with_the_same_result():
    seqs, labels = _seqs()
    win = training_windows(seqs, labels, 4)
    torch.manual_seed(0)
    net = SequenceNet(SmallCNN(2, 4, 2), frame_shape=(2, 9, 11), n_classes=3, hidden=6,
                      fc=8, dropout=0.0, input_size=8)
    bank = FrameBank(win, net.prepare)
    idx = np.flatnonzero(win.seq_index == 1)[:3]
    idx = np.concatenate([idx, [len(win) - 1]])  # and a window of another sequence
    full, y = bank.batch(idx)
    shared, y2 = bank.shared_batch(idx)
    assert isinstance(shared, SharedWindows) and torch.equal(y, y2)
    assert len(shared.frames) < full.shape[0] * full.shape[1]
    torch.testing.assert_close(shared.frames[shared.index], full)
    # the per-batch path gives the same distinct frames in the same order
    x = torch.from_numpy(win.batch(idx))
    flat = net.prepare(x.reshape(-1, *x.shape[2:])).reshape(*x.shape[:2], 2, 8, 8)
    read = share_frames(win, idx, flat)
    torch.testing.assert_close(read.frames, shared.frames)
    assert torch.equal(read.index, shared.index)
    # in eval mode (BatchNorm from running statistics) the logits are the same
    net.eval()
    with torch.no_grad():
        torch.testing.assert_close(net(shared), net(full), rtol=1e-5, atol=1e-6)


def test_shared_features_is_a_named_option_off_by_default(monkeypatch):
    reg = load_registry()
    assert reg.build("classifier", "small-cnn-lstm").shared_features == 0
    for bad in ("-1", "two"):
        with pytest.raises(InputError, match="shared_features"):
            reg.build("classifier", f"small-cnn-lstm:shared_features={bad}")
    train, test = tiny_windows(3, n=24, L=3)
    spec = "small-cnn-lstm:epochs=2,input_size=8,width=4,windows_per_epoch=40,batch_size=8"
    results = {}
    for budget in ("", "0"):  # frame bank, and read per batch
        monkeypatch.setenv("TACTBENCH_BANK_MIB", budget)
        clf = reg.build("classifier", spec + ",shared_features=1")
        report = clf.fit(train, seed=0)
        assert report["options"]["shared_features"] == 1
        results[budget] = clf.predict_proba(test)
    np.testing.assert_allclose(results[""], results["0"], rtol=1e-5, atol=1e-6)
    monkeypatch.delenv("TACTBENCH_BANK_MIB")
    plain = reg.build("classifier", spec)
    plain.fit(train, seed=0)
    assert not np.allclose(plain.predict_proba(test), results[""])  # other batches


def test_shared_features_change_nothing_at_L_1():
    """Windows of one frame share no frame: the same batches, the same model."""
    train, test = tiny_windows(3, n=24, L=1)
    spec = "small-cnn-lstm:epochs=1,input_size=8,width=4,windows_per_epoch=40,batch_size=8"
    reg = load_registry()
    out = []
    for extra in ("", ",shared_features=2"):
        clf = reg.build("classifier", spec + extra)
        clf.fit(train, seed=0)
        out.append(clf.predict_proba(test))
    np.testing.assert_array_equal(out[0], out[1])


def test_shared_features_work_for_taxel_vectors():
    train, test = tiny_windows(1, n=24, L=3)
    clf = load_registry().build("classifier", "taxel-lstm:epochs=1,windows_per_epoch=32,"
                                "batch_size=8,shared_features=1")
    report = clf.fit(train, seed=0)
    assert report["steps"] == 4
    assert clf.predict(test).shape == (len(test),)


def test_windows_grouping_needs_no_sorted_windows():
    seqs, labels = _seqs(n=3)
    win = training_windows(seqs, labels, 2)
    perm = np.random.default_rng(0).permutation(len(win))
    shuffled = Windows(win.sequences, win.seq_index[perm], win.starts[perm],
                       win.labels[perm], win.L)
    a, b = window_runs(win), window_runs(shuffled)
    assert np.array_equal(a[perm], b)


# --------------------------------------------------------------- shared frames, predicting


@pytest.mark.parametrize("spec", [
    "small-cnn-lstm:epochs=1,input_size=8,width=4,windows_per_epoch=40,batch_size=8",
    "taxel-lstm:epochs=1,windows_per_epoch=32,batch_size=8",
])
def test_voting_windows_encode_each_frame_once_with_the_same_probabilities(
        monkeypatch, spec):
    """Every window of a test sequence (the ``vote`` test window) overlaps its
    neighbours: prediction encodes each distinct frame once, batch boundaries included,
    and gives the plain path's probabilities."""
    import tactbench.classifiers.base as base

    train, _ = tiny_windows(1 if spec.startswith("taxel") else 3, n=24, L=3)
    clf = load_registry().build("classifier", spec)
    clf.fit(train, seed=0)
    clf.eval_batch_size = 7  # windows of one sequence split across forward passes
    vote = training_windows(train.sequences, train.labels[np.unique(train.seq_index,
                                                                     return_index=True)[1]], 3)
    assert base.shares_at_inference(vote, clf.net)
    encoded = []
    hook = clf.net.encoder.register_forward_hook(
        lambda module, args, out: encoded.append(len(args[0])))
    shared = clf.predict_proba(vote)
    n_shared = sum(encoded)
    encoded.clear()
    monkeypatch.setattr(base, "shares_at_inference", lambda windows, net: False)
    plain = clf.predict_proba(vote)
    hook.remove()
    np.testing.assert_allclose(shared, plain, rtol=1e-5, atol=1e-6)
    assert sum(encoded) == 3 * len(vote)
    # per forward pass, each distinct (sequence, frame) once, and one blank for padding
    lengths = np.array([s.shape[0] for s in vote.sequences])
    distinct = 0
    for lo in range(0, len(vote), 7):
        seq = vote.seq_index[lo:lo + 7, None]
        pos = vote.starts[lo:lo + 7, None] + np.arange(3)
        distinct += len({(int(a), int(b)) if b < lengths[a] else "blank"
                         for a, b in zip(np.broadcast_to(seq, pos.shape).ravel(), pos.ravel())})
    assert n_shared == distinct < sum(encoded)


def test_one_window_per_sequence_keeps_the_plain_path():
    from tactbench.classifiers.batching import shares_at_inference

    seqs, labels = _seqs()
    net = SequenceNet(SmallCNN(2, 4, 2), frame_shape=(2, 9, 11), n_classes=3, hidden=6,
                      fc=8, dropout=0.0, input_size=8)
    assert not shares_at_inference(test_windows(seqs, labels, 4), net)  # `first`
    assert not shares_at_inference(training_windows(seqs, labels, 1), net)  # L = 1
    assert shares_at_inference(training_windows(seqs, labels, 4), net)
    assert not shares_at_inference(training_windows(seqs, labels, 4), torch.nn.Identity())

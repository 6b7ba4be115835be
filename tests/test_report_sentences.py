"""Every stored report's sentence on what its runs allow is generated from all of that
report's results (issue 48): rendered again here from the results.json of every run it
names, it is the sentence in the report, and its counts and ranges are those of the
comparisons stored there. The README's families per report come from the same files."""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
REPORTS = REPO / "docs" / "reports"
DECIDED = ("B better", "A better", "equivalent")


def _reports_module():
    spec = importlib.util.spec_from_file_location("reports_bench", REPO / "benchmarks" /
                                                  "reports.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _notes():
    """(report.md, the sentence, the runs it names) of every stored report with one."""
    out = []
    for md in sorted(REPORTS.glob("*.md")):
        for line in md.read_text().splitlines():
            if line.startswith("- Counted over "):
                names = re.findall(r"`([^`]+)`", line.split(":")[0])
                out.append((md.name, line[2:], names))
    return out


def test_every_report_with_comparisons_has_its_note():
    assert {name for name, _, _ in _notes()} >= {"study.md", "real-data.md",
                                                 "which-flow.md", "which-classifier.md"}


@pytest.mark.parametrize("report, sentence, names", _notes(),
                         ids=[n for n, _, _ in _notes()])
def test_the_note_is_rendered_from_every_run_it_names(report, sentence, names):
    reports = _reports_module()
    parts = [{"out": REPORTS / n, "results": json.loads((REPORTS / n / "results.json")
                                                        .read_text())} for n in names]
    assert sentence == reports._runs_note(*parts)
    comps = [c for p in parts for c in p["results"]["comparisons"]]
    open_ = [c for c in comps if c["verdict"] not in DECIDED]
    assert f"up to {max(c['runs'] for c in comps)} runs per cell" in sentence
    if not open_:
        assert "is resolved." in sentence
        return
    assert "is resolved" not in sentence
    said = int(re.search(r"Of the (\d+) comparisons", sentence).group(1))
    assert said == len(open_)
    reach = [c["runs_for_power"] for c in open_ if c["runs_for_power"] is not None]
    if reach:
        assert re.search(rf"{len(reach)} would reach 80 % power at their observed "
                         rf"difference with {min(reach)}(–{max(reach)})? runs", sentence)
        assert f"for {len(open_) - len(reach)} no number of runs" in sentence
    else:
        assert "for every one no number of runs" in sentence
    shown = [c["detectable_effect"] for c in open_ if c["detectable_effect"] is not None]
    if shown:
        low, high = f"{min(shown):.1f}", f"{max(shown):.1f}"
        assert f"differences of {low if low == high else low + '–' + high} points" in sentence


def test_the_readme_counts_the_families_alpha_is_per():
    reports = _reports_module()
    said = reports._families_per_report(REPORTS)
    text = (REPO / "README.md").read_text()
    assert "α = 0.05 per run" in text and said in text
    study = sum(any(c.get("family") == "primary" for c in json.loads(f.read_text())
                    ["comparisons"]) for f in (REPORTS / "study").glob("*/results.json"))
    assert f"study: {study}" in said


# The README's findings (written by benchmarks/reports.py between its markers), each
# sentence that states a count, range or verdict checked here against the results.json
# it speaks of, computed again from the comparisons without the generator's helpers.
#: A findings bullet's link → the stored runs it speaks of.
BULLET_RUNS = {"The study, window length": ["study/lengths"],
               "Which flow?": ["which-flow/users"],
               "Which classifier?": ["which-classifier/images"],
               "Real data": ["real-data/cyskin-fingers", "real-data/icub-grasp"]}


def _results(name: str) -> dict:
    return json.loads((REPORTS / name / "results.json").read_text())


def _findings() -> list[str]:
    """The README's findings bullets, each joined into one line."""
    text = (REPO / "README.md").read_text()
    block = text.split("<!-- findings:", 1)[1].split("<!-- /findings -->", 1)[0]
    bullets, current = [], None
    for line in block.splitlines():
        if line.startswith("- "):
            current = line[2:]
            bullets.append(current)
        elif line.startswith("  ") and bullets:
            bullets[-1] = bullets[-1] + " " + line.strip()
    return bullets


def _bullets(title: str) -> list[str]:
    return [b for b in _findings() if b.startswith(f"[{title}]")]


@pytest.mark.parametrize("title", sorted(BULLET_RUNS))
def test_the_readme_counts_of_verdicts_are_the_results(title):
    """"Of its N paired comparisons, K reach a verdict … (R runs": N every comparison
    of the runs the bullet names, K those better either way or equivalent, R the run
    counts they have."""
    comps = [c for name in BULLET_RUNS[title] for c in _results(name)["comparisons"]]
    held = sum(c["verdict"] in DECIDED for c in comps)
    runs = "/".join(str(r) for r in sorted({c["runs"] for c in comps}))
    said = [b for b in _bullets(title) if "paired comparisons" in b]
    assert said, f"no count of verdicts for {title}"
    m = re.search(r"Of its (\d+) paired comparisons, (\d+) reach(?:es)? a verdict with the "
                  r"run as the unit \(([\d/]+) runs", said[-1])
    assert m and (int(m[1]), int(m[2]), m[3]) == (len(comps), held, runs), said[-1]


def test_the_readme_which_flow_count_is_the_results():
    comps = [c for c in _results("which-flow/users")["comparisons"]
             if c["factor"] == "encoder" and c["a"] == "raw"
             and "small-cnn-lstm" in str(c["classifier"])]
    better = [c for c in comps if c["verdict"] == "B better"]
    [said] = [b for b in _bullets("Which flow?") if "encoders are resolved better" in b]
    assert f"With the CNN, {len(better)} of {len(comps)} encoders are resolved better" in said


def test_the_readme_real_data_agreement_is_the_results():
    """"Every run favours the change in X of N comparisons and the raw vectors in Y":
    counted from the per-run differences themselves."""
    comps = [c for name in BULLET_RUNS["Real data"] for c in _results(name)["comparisons"]
             if c["factor"] == "encoder"]
    helped = sum(all(d > 0 for d in c["per_run"].values()) for c in comps)
    hurt = sum(all(d < 0 for d in c["per_run"].values()) for c in comps)
    [said] = [b for b in _bullets("Real data") if "Every run favours" in b]
    assert (f"Every run favours the change in {helped} of {len(comps)} comparisons and the "
            f"raw vectors in {hurt}") in said
    assert ("nothing here says the change helps" in said) == (helped == 0)


#: A primary bullet's link → (the stored runs, in the order it names them; A's and B's
#: names in its words for the comparisons' a and b).
PRIMARY_RUNS = {"The study's flagship": ["study/paper", "study/users", "study/people"],
                "Which classifier?": ["which-classifier/images"],
                "Which flow?": ["which-flow/users"],
                "Real data": ["real-data/cyskin-fingers", "real-data/icub-grasp"]}


def _answer_at(c: dict, said: str, at: int) -> int:
    """Where the answer to comparison ``c`` ends in ``said``, searched from ``at``: its
    verdict in bold (``**flow better**``, the better side named as the sentence names it
    in its "B − A"), its difference, interval and runs as stored."""
    if c.get("ceiling"):
        part = f"**a ceiling**: "
        found = said.find(part, at)
        assert found >= 0 and f"({c['runs']} runs)" in said[found:], c
        return found + len(part)
    numbers = (f"{100 * c['difference']:+.1f} points [{100 * c['low']:+.1f}, "
               f"{100 * c['high']:+.1f}] over {c['runs']} runs")
    m = re.compile(r"\*\*([^*]+)\*\*, (.+?) − (.+?) " + re.escape(numbers)).search(said, at)
    assert m, (c["a"], c["b"], numbers)
    word, b_name, a_name = m[1], m[2], m[3]
    want = {"B better": f"{b_name} better", "A better": f"{a_name} better"}.get(
        c["verdict"], c["verdict"])
    assert word == want or (c["verdict"] == "equivalent" and word.startswith("equivalent")), \
        (c["verdict"], word)
    return m.end()


@pytest.mark.parametrize("title", sorted(PRIMARY_RUNS))
def test_the_readme_primary_answers_are_the_results(title):
    """Each primary comparison's answer in the README — its verdict (the better side
    named), difference, interval and runs — is the stored comparison's, in the order
    stored, and the bullet names no other."""
    comps = [c for name in PRIMARY_RUNS[title] for c in _results(name)["comparisons"]
             if c.get("family") == "primary"]
    [said] = [b for b in _bullets(title) if "**" in b]
    assert len(re.findall(r"\*\*([^*]+)\*\*", said)) == len(comps), title
    at = 0
    for c in comps:
        at = _answer_at(c, said, at)


def test_the_readme_window_length_answer_is_the_contrast():
    [c] = [c for c in _results("study/lengths")["comparisons"] if c.get("family") == "primary"]
    [said] = _bullets("The study's window length")
    _answer_at(c, said, 0)


ANSWER = re.compile(
    r"^- .*?: (?P<b>[^:]+?) − (?P<a>[^:]+?): (?P<d>[+-]\d+\.\d) points, 95 % interval over "
    r"runs \[(?P<lo>[+-]\d+\.\d), (?P<hi>[+-]\d+\.\d)\] \(unadjusted\), (?P<k>\d+) of "
    r"(?P<j>\d+) runs higher, .*?\((?P<family>primary|exploratory), (?P<m>\d+)\) → "
    r"\*\*(?P<word>[^*]+)\*\*")


def _answer_lines():
    """(report, line) of every report sentence that gives one comparison's answer."""
    return [(md.name, line) for md in sorted(REPORTS.glob("*.md"))
            for line in md.read_text().splitlines() if ANSWER.match(line)]


def test_the_reports_answer_sentences_are_found():
    assert {name for name, _ in _answer_lines()} >= {"study.md", "real-data.md",
                                                     "which-classifier.md"}


@pytest.mark.parametrize("report, line", _answer_lines(),
                         ids=[f"{n}:{i}" for i, (n, _) in enumerate(_answer_lines())])
def test_each_answer_sentence_is_a_stored_comparison(report, line):
    """A report's "B − A: d points, [lo, hi], k of J runs higher, (family, m) → verdict"
    is a comparison stored in one of that report's results.json: the same rounded
    difference and interval, k runs where B was higher of J, its family and the
    family's size, and the verdict (the better side named as the sentence names it)."""
    m = ANSWER.match(line)
    comps = [c for f in sorted((REPORTS / report.removesuffix(".md")).rglob("results.json"))
             for c in json.loads(f.read_text())["comparisons"]]
    same = [c for c in comps if not c.get("ceiling")
            and f"{100 * c['difference']:+.1f}" == m["d"]
            and f"{100 * c['low']:+.1f}" == m["lo"] and f"{100 * c['high']:+.1f}" == m["hi"]
            and c["runs"] == int(m["j"]) and c.get("family") == m["family"]]
    assert same, line
    want = {"B better": f"{m['b']} better", "A better": f"{m['a']} better"}
    ok = [c for c in same if c["b_better_runs"] == int(m["k"])
          and c.get("family_size") == int(m["m"])
          and (m["word"] == want.get(c["verdict"], c["verdict"])
               or (c["verdict"] == "equivalent" and m["word"].startswith("equivalent")))]
    assert ok, (line, [(c["b_better_runs"], c.get("family_size"), c["verdict"]) for c in same])

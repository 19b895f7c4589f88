"""`make bench` (bench/run_all.py) writes docs/benchmarks.md afresh: the figures of this
run, then bench/findings.md, where what the figures mean is kept by hand. A finding
written into docs/benchmarks.md alone would be lost at the next run."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_the_benchmarks_page_ends_with_the_findings_kept_by_hand() -> None:
    findings = (ROOT / "bench" / "findings.md").read_text()
    page = (ROOT / "docs" / "benchmarks.md").read_text()
    assert findings.strip(), "bench/findings.md is empty"
    assert page.endswith(findings), (
        "docs/benchmarks.md does not end with bench/findings.md: write findings into"
        " bench/findings.md and copy it to the page's end (make bench does)"
    )

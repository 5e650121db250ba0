"""The combined table of several runs (e.g. the three thesis sites)."""

from __future__ import annotations

import json
from pathlib import Path

from femstudy import atomic
from femstudy.study.report import study_discussion, study_table


def write_study(folder: Path, summaries: list[dict]) -> Path:
    """Write ``study.md`` (table beside Tables 5-14/5-15 plus discussion) and ``study.json``."""
    text = "\n".join(["# Drilling study: all sites", "", study_table(summaries), "", study_discussion(summaries)])
    folder = Path(folder)
    atomic.write_text(folder / "study.md", text)
    atomic.write_text(folder / "study.json", json.dumps(
        [{"case": s["case"]["name"], "site": s["site"]["name"], "results": s["results"]} for s in summaries], indent=2))
    return folder / "study.md"

"""Run ``femstudy diagnose`` on the independent cases as a user would, and score it per class.

Each case goes through the command line in-process (``femstudy diagnose REC --simulation SIM
--json OUT``), so a refusal is what a user sees: exit status 2 and one line. The score of a
case:

- named classes and complete cases: the mechanisms reported against the truth (TP/FP/FN for
  each catalogue mechanism, exact set);
- decoys: "caught" when none of the four catalogue mechanisms is named and either an
  ``unexplained`` entry overlaps the decoy's interval (±0.5 s) or a new catalogue name that
  fits the decoy is reported; "described" when that entry's kind is the decoy's kind;
- every case: refused or not, whether a held-out R² is reported, the time.
"""

from __future__ import annotations

import contextlib
import io
import json
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

from bench.independent.cases import CLASSES, DECOYS, Case

FOUR = ("chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening")

#: new catalogue names that count as a correct answer to a decoy
FITTING_NAMES = {"spindle": {"spindle_slowdown"}, "timing": {"feed_rate_error", "clock_error"},
                 "step": {"load_step"}, "torque_only": {"torque_friction_change"}}


@dataclass
class Outcome:
    case: Case
    refused: str | None
    found: frozenset[str]
    unexplained: list[dict]
    result: dict | None
    seconds: float

    @property
    def four(self) -> frozenset[str]:
        return frozenset(m for m in self.found if m in FOUR)

    def decoy_caught(self) -> bool:
        d = self.case.decoy
        if d is None or self.refused:
            return False
        if self.four:
            return False
        if self.found & FITTING_NAMES.get(d["kind"], set()):
            return True
        return any(u["end_s"] >= d["start_s"] - 0.5 and u["start_s"] <= d["end_s"] + 0.5 for u in self.unexplained)

    def decoy_described(self) -> bool:
        d = self.case.decoy
        if not self.decoy_caught():
            return False
        if self.found & FITTING_NAMES.get(d["kind"], set()):
            return True
        return any(u.get("kind") == d["kind"] for u in self.unexplained)

    def heldout_r2(self) -> float | None:
        if self.result is None:
            return None
        return self.result.get("fit", {}).get("improved", {}).get("r2_heldout")


def diagnose_case(case: Case, out_dir: Path) -> Outcome:
    """Run the command on one case and read its JSON."""
    from femstudy.cli import main

    out = out_dir / f"{case.name}.diagnosis.json"
    out.unlink(missing_ok=True)
    stderr = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(stderr):
        status = main(["diagnose", str(case.recording), "--simulation", str(case.simulation),
                       "--json", str(out), "--quiet"])
    seconds = time.perf_counter() - start
    if status != 0:
        return Outcome(case, stderr.getvalue().strip() or f"exit {status}", frozenset(), [], None, seconds)
    result = json.loads(out.read_text())
    found = frozenset(m["mechanism"] for m in result.get("missing_physics", []))
    return Outcome(case, None, found, list(result.get("unexplained", [])), result, seconds)


def _short(names) -> str:
    short = {"chip_clogging": "clog", "feed_pulsation": "puls", "sensor_drift": "drift",
             "thermal_softening": "soft"}
    return "+".join(sorted(short.get(n, n) for n in names)) or "-"


def case_line(o: Outcome) -> str:
    c = o.case
    truth = _short(c.truth) if c.decoy is None else f"decoy:{c.decoy['kind']}"
    if o.refused:
        return f"{c.name:34s} {truth:22s} REFUSED: {o.refused[:110]}"
    if c.decoy is None:
        ok = "yes" if o.found == c.truth else "NO"
    else:
        ok = ("yes" if o.decoy_described() else "caught") if o.decoy_caught() else "NO"
    kinds = ",".join(u.get("kind", "?") for u in o.unexplained) or "-"
    r2 = o.heldout_r2()
    fit = (o.result or {}).get("fit", {})
    before = fit.get("baseline", {}).get("r2", float("nan"))
    after = fit.get("improved", {}).get("r2", float("nan"))
    held = f"{r2:7.3f}" if isinstance(r2, (int, float)) else "   n/a "
    return (f"{c.name:34s} {truth:22s} {_short(o.found):22s} {ok:6s} unexpl[{kinds[:30]}] "
            f"R2 {before:6.3f}->{after:6.3f} held {held} {o.seconds:5.2f}s")


def summary(outcomes: list[Outcome]) -> str:
    """Per-class table, per-mechanism F1 over the named classes, decoy and refusal counts."""
    lines = [f"{'class':26s} {'n':>3s} {'refused':>7s} {'exact':>6s} {'named-4 wrong':>13s} "
             f"{'decoy caught':>12s} {'described':>9s} {'unexpl.':>7s} {'max s':>6s}"]
    for kind in CLASSES:
        rows = [o for o in outcomes if o.case.kind == kind]
        if not rows:
            continue
        refused = sum(1 for o in rows if o.refused)
        if kind in DECOYS:
            exact = "-"
            wrong = sum(1 for o in rows if o.four)
            caught = f"{sum(o.decoy_caught() for o in rows)}/{len(rows)}"
            described = f"{sum(o.decoy_described() for o in rows)}/{len(rows)}"
        else:
            exact = f"{sum(1 for o in rows if not o.refused and o.found == o.case.truth)}/{len(rows)}"
            wrong = sum(1 for o in rows if o.four != o.case.truth)
            caught = described = "-"
        unexplained = sum(1 for o in rows if o.unexplained)
        lines.append(f"{kind:26s} {len(rows):3d} {refused:7d} {exact:>6s} {wrong:13d} {caught:>12s} "
                     f"{described:>9s} {unexplained:7d} {max(o.seconds for o in rows):6.2f}")
    named = [o for o in outcomes if o.case.decoy is None]
    lines.append("")
    lines.append(f"{'mechanism (named + complete classes)':38s} {'TP':>3s} {'FP':>3s} {'FN':>3s} {'F1':>6s}")
    tp_all = fp_all = fn_all = 0
    for m in FOUR:
        tp = sum(1 for o in named if m in o.found and m in o.case.truth)
        fp = sum(1 for o in named if m in o.found and m not in o.case.truth)
        fn = sum(1 for o in named if m not in o.found and m in o.case.truth)
        tp_all, fp_all, fn_all = tp_all + tp, fp_all + fp, fn_all + fn
        f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else float("nan")
        lines.append(f"{m:38s} {tp:3d} {fp:3d} {fn:3d} {f1:6.3f}")
    f1 = 2 * tp_all / (2 * tp_all + fp_all + fn_all) if tp_all + fp_all + fn_all else float("nan")
    lines.append(f"{'all four (micro-averaged)':38s} {tp_all:3d} {fp_all:3d} {fn_all:3d} {f1:6.3f}")
    complete = [o for o in outcomes if o.case.decoy is None and not o.case.truth]
    decoys = [o for o in outcomes if o.case.decoy is not None]
    refused = [o for o in outcomes if o.refused]
    held = [o for o in outcomes if isinstance(o.heldout_r2(), (int, float))]
    times = [o.seconds for o in outcomes]
    lines += ["",
              f"cases {len(outcomes)}; refused {len(refused)}",
              f"false alarms on complete cases: {sum(1 for o in complete if o.found)}/{len(complete)} "
              f"(with an 'unexplained' entry: {sum(1 for o in complete if o.unexplained)})",
              f"decoys caught {sum(o.decoy_caught() for o in decoys)}/{len(decoys)}, described "
              f"{sum(o.decoy_described() for o in decoys)}/{len(decoys)}, named as one of the four "
              f"{sum(1 for o in decoys if o.four)}/{len(decoys)}",
              f"held-out R2 reported {len(held)}/{len(outcomes)}",
              f"time per case: median {statistics.median(times):.2f} s, max {max(times):.2f} s"]
    return "\n".join(lines)

"""Run ``femstudy diagnose`` on form-randomised cases as a user would, and score the answers.

Each case goes through the command line in-process (``femstudy diagnose REC --simulation SIM
--json OUT``): a refusal is what a user sees, exit status 2. The score:

- named and complete classes: each catalogue mechanism named against the truth (TP, FP, FN per
  mechanism; F1 micro-averaged over the four), the exact set, false alarms on complete cases;
- decoys: *caught* when none of the four is named and an ``unexplained`` entry overlaps the
  decoy's interval (±0.5 s; a channel fault's interval is the whole record); *named* when one of
  the four is named; *described* when the entry's kind is one that fits the decoy
  (:data:`FITTING_KINDS`);
- confidence: every named mechanism with its confidence and whether it is right, for the
  reliability table (:func:`reliability`);
- time: per case, and per 20 s, 1 kHz recording (the long cases): wall, and CPU summed over the
  process and its fitting workers.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

FOUR = ("chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening")
#: the unexplained kinds that describe each decoy
FITTING_KINDS = {
    "chip_break": {"step"}, "hard_layer": {"bump"}, "soft_layer": {"bump"}, "spindle_slowdown": {"spindle", "load_power"},
    "feed_error": {"timing"}, "clock_error": {"timing"}, "thrust_wobble": {"oscillation"},
    "torque_friction": {"torque_only"}, "second_cortex": {"bump", "step", "second_cut"},
    "fixture_vibration": {"oscillation"}, "air_knock": {"air_event"}, "tare_jump": {"air_event", "zero_jump"},
    "second_touch": {"air_event"}, "polarity": {"polarity"}, "swapped": {"swapped_channels"},
    "cross_talk": {"cross_talk", "channel_scale"}, "unit_scale": {"unit_scale"}, "saturation": {"clipping"},
}
#: confidence bins of the reliability table
BINS = (0.0, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0001)


@dataclass
class Outcome:
    case: dict                    # the case's truth.json
    refused: str | None
    named: dict                   # mechanism -> confidence
    unexplained: list
    result: dict | None
    seconds: float
    cpu_seconds: float = float("nan")
    evidence: dict | None = None  # mechanism -> the evidence its confidence rests on
    dropped: dict | None = None   # mechanism dropped by its confidence -> {"confidence", "evidence"}

    @property
    def decoy(self) -> dict | None:
        return self.case["decoy"]

    @property
    def truth(self) -> frozenset:
        return frozenset(self.case["truth"])

    @property
    def four(self) -> frozenset:
        return frozenset(m for m in self.named if m in FOUR)

    def caught(self) -> bool:
        d = self.decoy
        if d is None or self.refused or self.four:
            return False
        return any(u["end_s"] >= d["start_s"] - 0.5 and u["start_s"] <= d["end_s"] + 0.5 for u in self.unexplained)

    def described(self) -> bool:
        return self.caught() and any(u.get("kind") in FITTING_KINDS[self.decoy["kind"]] for u in self.unexplained)

    def to_json(self) -> dict:
        return {"name": self.case["name"], "class": self.case["class"], "split": self.case["split"],
                "truth": sorted(self.truth), "forms": self.case["forms"], "decoy": self.decoy,
                "refused": self.refused, "named": self.named,
                "unexplained": [{k: u[k] for k in ("start_s", "end_s", "channel", "kind")} for u in self.unexplained],
                "seconds": round(self.seconds, 3), "cpu_seconds": round(self.cpu_seconds, 3), "long": self.case["long"]}


def _cpu_seconds() -> float:
    """CPU time [s] of this process and of its ended children (the diagnosis's fitting workers)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def diagnose_case(truth_path: Path, workers: int | None = None) -> Outcome:
    """The command on one case (its ``.truth.json``), and its JSON read back; ``workers``: the
    command's ``--workers`` (default: its own, one per core)."""
    from femstudy.cli import main

    case = json.loads(truth_path.read_text())
    folder = truth_path.parent
    out = folder / f"{case['name']}.diagnosis.json"
    out.unlink(missing_ok=True)
    stderr = io.StringIO()
    start, cpu = time.perf_counter(), _cpu_seconds()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(stderr):
        status = main(["diagnose", str(folder / case["recording"]), "--simulation", str(folder / case["simulation"]),
                       "--json", str(out), "--quiet"] + ([] if workers is None else ["--workers", str(workers)]))
    seconds, cpu = time.perf_counter() - start, _cpu_seconds() - cpu
    if status != 0:
        return Outcome(case, stderr.getvalue().strip() or f"exit {status}", {}, [], None, seconds, cpu)
    result = json.loads(out.read_text())
    named = {m["mechanism"]: float(m.get("confidence", 1.0)) for m in result.get("missing_physics", [])}
    evidence = {m["mechanism"]: m.get("evidence", {}) for m in result.get("missing_physics", [])}
    dropped = result.get("selection", {}).get("dropped_by_confidence", {})
    return Outcome(case, None, named, list(result.get("unexplained", [])), result, seconds, cpu, evidence, dropped)


def _short(names) -> str:
    short = {"chip_clogging": "clog", "feed_pulsation": "puls", "sensor_drift": "drift", "thermal_softening": "soft"}
    return "+".join(sorted(short.get(n, n) for n in names)) or "-"


def case_line(o: Outcome) -> str:
    c = o.case
    if o.refused:
        return f"{c['name']:44s} REFUSED: {o.refused[:120]}"
    if o.decoy is None:
        truth, ok = _short(o.truth), "yes" if o.four == o.truth else "NO"
    else:
        truth, ok = "decoy", ("yes" if o.described() else "caught") if o.caught() else "NO"
    forms = ",".join(f"{_short([m])}:{f}" for m, f in sorted(c["forms"].items()))
    kinds = ",".join(u.get("kind", "?") for u in o.unexplained) or "-"
    conf = ",".join(f"{_short([m])}:{v:.2f}" for m, v in sorted(o.named.items()))
    return (f"{c['name']:44s} {truth:16s} {_short(o.four):16s} {ok:6s} [{forms[:44]}] conf[{conf}] "
            f"unexpl[{kinds[:40]}] {o.seconds:5.2f}s cpu {o.cpu_seconds:5.2f}s")


def f1_counts(outcomes: list[Outcome]) -> dict:
    """TP, FP, FN per mechanism over the named and complete classes, and micro-averaged."""
    named = [o for o in outcomes if o.decoy is None]
    out = {}
    for m in FOUR:
        tp = sum(1 for o in named if m in o.four and m in o.truth)
        fp = sum(1 for o in named if m in o.four and m not in o.truth)
        fn = sum(1 for o in named if m not in o.four and m in o.truth)
        out[m] = (tp, fp, fn)
    out["all"] = tuple(sum(v[i] for v in out.values()) for i in range(3))
    return out


def f1(tp: int, fp: int, fn: int) -> float:
    return 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else float("nan")


def summary(outcomes: list[Outcome]) -> str:
    """Per-class table, per-mechanism F1, the targets' figures and the time."""
    lines = [f"{'class':34s} {'n':>3s} {'refused':>7s} {'exact':>6s} {'named-4 wrong':>13s} {'caught':>7s} "
             f"{'described':>9s} {'max s':>6s}"]
    for kind in dict.fromkeys(o.case["class"] for o in outcomes):
        rows = [o for o in outcomes if o.case["class"] == kind]
        refused = sum(1 for o in rows if o.refused)
        if kind.startswith("decoy:"):
            exact, wrong = "-", sum(1 for o in rows if o.four)
            caught = f"{sum(o.caught() for o in rows)}/{len(rows)}"
            described = f"{sum(o.described() for o in rows)}/{len(rows)}"
        else:
            exact = f"{sum(1 for o in rows if not o.refused and o.four == o.truth)}/{len(rows)}"
            wrong = sum(1 for o in rows if o.four != o.truth)
            caught = described = "-"
        lines.append(f"{kind:34s} {len(rows):3d} {refused:7d} {exact:>6s} {wrong:13d} {caught:>7s} {described:>9s} "
                     f"{max(o.seconds for o in rows):6.2f}")
    counts = f1_counts(outcomes)
    lines += ["", f"{'mechanism':28s} {'TP':>4s} {'FP':>4s} {'FN':>4s} {'F1':>6s}"]
    for m in FOUR + ("all",):
        tp, fp, fn = counts[m]
        lines.append(f"{m if m != 'all' else 'all four (micro-averaged)':28s} {tp:4d} {fp:4d} {fn:4d} {f1(tp, fp, fn):6.3f}")
    by_form: dict = {}
    for o in outcomes:
        for m, form in o.case["forms"].items():
            key = (m, form)
            tp_fn = by_form.setdefault(key, [0, 0])
            tp_fn[0 if m in o.four else 1] += 1
    lines += ["", "recall by form: " + ", ".join(f"{_short([m])}:{f} {a}/{a + b}" for (m, f), (a, b) in sorted(by_form.items()))]
    complete = [o for o in outcomes if o.decoy is None and not o.truth]
    decoys = [o for o in outcomes if o.decoy is not None]
    refused = [o for o in outcomes if o.refused]
    times = [o.seconds for o in outcomes]
    long = [o.seconds for o in outcomes if o.case["long"]]
    cpu = [o.cpu_seconds for o in outcomes]
    long_cpu = [o.cpu_seconds for o in outcomes if o.case["long"]]
    lines += ["",
              f"cases {len(outcomes)}; refused {len(refused)}",
              f"false alarms on complete cases: {sum(1 for o in complete if o.four)}/{len(complete)} "
              f"(with an 'unexplained' entry: {sum(1 for o in complete if o.unexplained)})",
              f"decoys caught {sum(o.caught() for o in decoys)}/{len(decoys)}, described "
              f"{sum(o.described() for o in decoys)}/{len(decoys)}, named as one of the four "
              f"{sum(1 for o in decoys if o.four)}/{len(decoys)}",
              f"time per case (wall): median {statistics.median(times):.2f} s, max {max(times):.2f} s"
              + (f"; 18-22 s recordings at 1 kHz ({len(long)}): max {max(long):.2f} s" if long else ""),
              f"time per case (CPU, with the fitting workers): median {statistics.median(cpu):.2f} s, max {max(cpu):.2f} s"
              + (f"; 18-22 s recordings at 1 kHz: median {statistics.median(long_cpu):.2f} s, max {max(long_cpu):.2f} s"
                 if long_cpu else "")]
    return "\n".join(lines)


def reliability(outcomes: list[Outcome]) -> list[tuple[float, float, int, int, float]]:
    """(low, high, named, right, mean confidence) per confidence bin, over every named mechanism."""
    rows = []
    pairs = [(c, m in o.truth) for o in outcomes if not o.refused for m, c in o.named.items() if m in FOUR]
    for lo, hi in zip(BINS[:-1], BINS[1:]):
        inside = [(c, ok) for c, ok in pairs if lo <= c < hi]
        if inside:
            rows.append((lo, min(hi, 1.0), len(inside), sum(ok for _, ok in inside),
                         statistics.mean(c for c, _ in inside)))
    return rows


def reliability_table(outcomes: list[Outcome]) -> str:
    lines = [f"{'confidence':>12s} {'named':>6s} {'right':>6s} {'fraction right':>15s} {'mean confidence':>16s}"]
    for lo, hi, n, right, mean in reliability(outcomes):
        lines.append(f"{lo:5.2f}-{hi:4.2f} {n:8d} {right:6d} {right / n:15.3f} {mean:16.3f}")
    return "\n".join(lines)

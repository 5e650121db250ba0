"""Answers kept between runs (femstudy.kept_answers): found only under identical inputs,
recomputed when the stored file is damaged, never keyed by identity."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from femstudy.kept_answers import digest, kept_answer


@dataclass(frozen=True)
class Inputs:
    feed_mm_s: float
    fields: np.ndarray
    name: str = "case"


def test_the_digest_reads_content_not_identity():
    fields = np.arange(6.0).reshape(3, 2)
    key = digest(Inputs(2.0, fields), "solver")
    assert digest(Inputs(2.0, fields.copy()), "solver") == key  # another object, the same content
    changed = fields.copy()
    changed[1, 1] += 1e-12
    others = [digest(Inputs(2.0, changed), "solver"),               # one value 1e-12 off
              digest(Inputs(2.0 + 1e-15, fields), "solver"),        # the last bits of a float
              digest(Inputs(2.0, fields.astype(np.float32)), "solver"),
              digest(Inputs(2.0, fields.reshape(2, 3)), "solver"),  # same bytes, other shape
              digest(Inputs(2.0, fields), "other solver"),
              digest([Inputs(2.0, fields), "solver"]),              # a list is not the parts
              digest({"a": 1, "b": 2}), digest({"a": 2, "b": 1})]
    assert len({key, *others}) == len(others) + 1
    assert digest({"a": 1, "b": 2}) == digest({"b": 2, "a": 1})  # a dict's order is not content
    assert digest(Path("a/b")) != digest("a/b")


@pytest.mark.parametrize("part", [lambda x: x, object(), np.array([object()])])
def test_what_has_no_readable_content_is_refused_not_keyed_by_identity(part):
    with pytest.raises(TypeError, match="cannot key"):
        digest(part)


def test_an_answer_is_computed_once_and_read_back_marked(tmp_path):
    calls = []

    def compute():
        calls.append(1)
        return {"peak_mm": 0.035, "field": np.linspace(0, 1, 5)}

    def mark(answer):
        return {**answer, "kept": True}

    first = kept_answer(tmp_path, "hole models", (Inputs(2.0, np.ones(3)),), compute, mark)
    again = kept_answer(tmp_path, "hole models", (Inputs(2.0, np.ones(3)),), compute, mark)
    other = kept_answer(tmp_path, "hole models", (Inputs(2.5, np.ones(3)),), compute, mark)
    assert len(calls) == 2 and "kept" not in first and "kept" not in other
    assert again["kept"] and again["peak_mm"] == first["peak_mm"] and np.array_equal(again["field"], first["field"])
    assert len(list(tmp_path.glob("hole-models-*.pickle"))) == 2
    kept_answer(None, "hole models", (Inputs(2.0, np.ones(3)),), compute, mark)  # nothing kept: computed
    assert len(calls) == 3


def test_a_damaged_answer_is_recomputed_and_replaced(tmp_path, caplog):
    compute = iter([1.0, 2.0, 3.0]).__next__
    assert kept_answer(tmp_path, "sensitivity", ("a",), compute) == 1.0
    (stored,) = tmp_path.glob("sensitivity-*.pickle")
    stored.write_bytes(stored.read_bytes()[:10])  # cut short, as by a full disk
    with caplog.at_level(logging.WARNING):
        assert kept_answer(tmp_path, "sensitivity", ("a",), compute) == 2.0
    assert "ignoring unreadable kept sensitivity" in caplog.text
    assert kept_answer(tmp_path, "sensitivity", ("a",), compute) == 2.0  # the recomputed one was kept


def test_an_unwritable_folder_costs_a_recomputation_not_the_run(tmp_path, caplog):
    blocked = tmp_path / "file"
    blocked.write_text("not a folder")
    with caplog.at_level(logging.WARNING):
        assert kept_answer(blocked, "resolved transient", ("a",), lambda: 7) == 7
    assert "could not keep the resolved transient" in caplog.text


def test_an_answer_not_worth_keeping_is_computed_every_time(tmp_path):
    calls = []

    def compute():
        calls.append(1)
        return np.zeros(10)

    for _ in range(2):
        kept_answer(tmp_path, "assembly", ("mesh",), compute, worth_keeping=lambda answer: answer.size < 10)
    assert len(calls) == 2 and not list(tmp_path.glob("assembly-*.pickle"))

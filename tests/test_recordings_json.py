"""JSON recordings (femstudy/recordings/formats/jsonfile.py): a format added as one module."""

import json

import numpy as np
import pytest

from femstudy.errors import UserError
from femstudy.recordings.reader import read_recording


def test_a_json_recording_is_read_with_its_units_and_metadata(tmp_path):
    t = np.arange(2000) * 1.0  # ms
    document = {"metadata": {"feed_mm_s": 1.5, "spindle_rpm": 1500, "specimen": "bovine 3"},
                "units": {"t": "ms", "Fz": "kN"},
                "columns": {"t": t.tolist(), "Fz": (0.001 * np.sin(t / 100) + 0.002).tolist(),
                            "torque_Nm": (0.01 * np.cos(t / 50)).tolist()}}
    (tmp_path / "run.json").write_text(json.dumps(document))
    rec = read_recording(tmp_path / "run.json")
    np.testing.assert_allclose(rec.time_s, t / 1000)
    np.testing.assert_allclose(rec.thrust_N, 1000 * np.asarray(document["columns"]["Fz"]))
    np.testing.assert_allclose(rec.torque_Nmm, 1000 * np.asarray(document["columns"]["torque_Nm"]))
    assert rec.feed_mm_s == 1.5 and rec.metadata["specimen"] == "bovine 3"


@pytest.mark.parametrize("text, message", [
    ("{not json", "not readable JSON"),
    ('{"columns": []}', 'needs an object with "columns"'),
    ('{"metadata": {"feed_mm_s": 1, "spindle_rpm": 1000}, "columns": {"time_s": [0, 0.001], "thrust_N": [1]}}',
     "differ in length"),
    ('{"metadata": {"feed_mm_s": 1, "spindle_rpm": 1000}, "columns": {"time_s": [0, "a"], "thrust_N": [1, 2]}}',
     "must be a list of numbers"),
])
def test_a_malformed_json_recording_is_refused_in_one_sentence(tmp_path, text, message):
    (tmp_path / "bad.json").write_text(text)
    with pytest.raises(UserError, match=message):
        read_recording(tmp_path / "bad.json")

"""The recording reader: format, units, metadata, overrides and every bad input."""

import numpy as np
import pytest

from femstudy.errors import UserError
from femstudy.recordings import Effects, read_recording, synthesize, write_recording

HEADER = "# feed_mm_s = 1.5\n# spindle_rpm = 1500\n"


def rows(n=400, rate=1000.0, torque=True):
    """A small valid body: a thrust bump, sampled at ``rate``."""
    t = np.arange(n) / rate
    f = 10 * np.exp(-((t - t.mean()) / 0.05) ** 2)
    cols = [t, f, 2 * f] if torque else [t, f]
    return "\n".join(",".join(f"{v:.6g}" for v in r) for r in zip(*cols)) + "\n"


def write(tmp_path, text, name="rec.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_round_trip_keeps_samples_and_every_header_value(tmp_path):
    rec = synthesize(1.5, 1500, seed=4, depth_column=True)
    write_recording(tmp_path / "r.csv", rec)
    back = read_recording(tmp_path / "r.csv")
    np.testing.assert_allclose(back.time_s, rec.time_s, atol=1e-9)
    np.testing.assert_allclose(back.thrust_N, rec.thrust_N, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(back.torque_Nmm, rec.torque_Nmm, rtol=1e-5, atol=1e-5)
    np.testing.assert_allclose(back.depth_mm, rec.depth_mm, rtol=1e-5, atol=1e-5)
    for key, value in rec.metadata.items():
        assert back.metadata[key] == (pytest.approx(value) if isinstance(value, float) else value), key
    assert back.metadata["samples"] == rec.time_s.size
    assert back.sample_rate_hz == pytest.approx(1000.0)
    assert back.drill.cone_length_mm == pytest.approx(1.35)


def test_torque_in_newton_metres_is_converted_explicitly(tmp_path):
    body = rows()
    nm = "".join(",".join([a, b, f"{float(c) / 1000:.9g}"]) + "\n"
                 for a, b, c in (line.split(",") for line in body.splitlines()))
    a = read_recording(write(tmp_path, HEADER + "time_s,thrust_N,torque_Nmm\n" + body, "a.csv"))
    b = read_recording(write(tmp_path, HEADER + "time_s,thrust_N,torque_Nm\n" + nm, "b.csv"))
    np.testing.assert_allclose(b.torque_Nmm, a.torque_Nmm, rtol=1e-12, atol=1e-12)
    assert b.notes == ("torque_Nm converted from Nm to N·mm (x1000)",)
    assert not a.notes


def test_extra_columns_and_free_comments_are_ignored_torque_is_optional(tmp_path):
    text = "# recorded on the CNC rig, sensor tared\n" + HEADER + "sample,time_s,thrust_N,tx_Nmm\n"
    text += "".join(f"{k},{line.split(',')[0]},{line.split(',')[1]},0\n" for k, line in
                    enumerate(rows(torque=False).splitlines()))
    rec = read_recording(write(tmp_path, text))
    assert rec.torque_Nmm is None and rec.thrust_N.size == 400


def test_command_line_values_must_agree_with_the_header_unless_overridden(tmp_path):
    path = write(tmp_path, HEADER + "time_s,thrust_N\n" + rows(torque=False))
    assert read_recording(path, {"feed_mm_s": 1.5}).feed_mm_s == 1.5  # agreeing is fine
    with pytest.raises(UserError, match=r"header says feed_mm_s = 1.5 but the command line says 2.0.*--override"):
        read_recording(path, {"feed_mm_s": 2.0})
    rec = read_recording(path, {"feed_mm_s": 2.0}, override_header=True)
    assert rec.feed_mm_s == 2.0
    assert rec.notes == ("feed_mm_s = 2.0 from the command line overrides 1.5 in the header",)


def test_absent_metadata_can_come_from_the_command_line(tmp_path):
    path = write(tmp_path, "# spindle_rpm = 1500\ntime_s,thrust_N\n" + rows(torque=False))
    with pytest.raises(UserError, match=r"rec.csv has no feed_mm_s: add '# feed_mm_s = \.\.\.'"):
        read_recording(path)
    assert read_recording(path, {"feed_mm_s": 1.0}).feed_mm_s == 1.0


BAD = [
    ("", "recording rec.csv is empty"),
    (HEADER, "has no column line"),
    (HEADER + "time_s,thrust_N\n", "has a column line but no data rows"),
    (HEADER + "time_s,torque_Nmm\n0,1\n",
     "has no thrust_N column (newtons), nor another thrust column (fz, thrust) with a unit; its columns are: "
     "time_s, torque_Nmm"),
    (HEADER + "time,thrust_N\n0,1\n", "column 'time' has no unit; name it time_s (seconds)"),
    (HEADER + "time_s,thrust_N,torque\n0,1,2\n",
     "column 'torque' has no unit; name it torque_Nmm (N·mm) or torque_Nm (N·m)"),
    (HEADER + "time_s,thrust_mm\n0,1\n",
     "column 'thrust_mm' is in mm (a length); thrust needs a force unit such as N, kN or lbf"),
    (HEADER + "time_s,thrust_N,torque_N\n0,1,2\n",
     "column 'torque_N' is in N (a force); torque needs a torque unit such as N·mm, N·m or lbf·in"),
    (HEADER + "time_s,thrust_furlong\n0,1\n",
     "column 'thrust_furlong' is in furlong (a length)"),
    (HEADER + "time_s,thrust_Newtons\n0,1\n",
     "column 'thrust_Newtons' has unit 'Newtons', which is not a unit femstudy knows; thrust needs a force unit"),
    (HEADER + "time_s,thrust_N,torque_Nm,torque_Nmm\n0,1,2,3\n", "has two torque columns"),
    (HEADER + "time_s,thrust_N\n0,1\n0.001,nan\n0.002,3\n", "thrust_N is nan at line 5"),
    (HEADER + "time_s,thrust_N\n0,1\n0.001,2\n0.002,-inf\n", "thrust_N is -inf at line 6"),
    (HEADER + "time_s,thrust_N\n0,1\n0.001,\n", "line 5: an empty field in column 2 is not a number"),
    (HEADER + "time_s,thrust_N\n0,1\n0.001,abc\n", "line 5: abc in column 2 is not a number"),
    (HEADER + "time_s,thrust_N\n0,1\n0.001\n", "line 5: 1 values, expected one per column"),
    (HEADER + "time_s,thrust_N\n0,1\n0.002,2\n0.001,3\n0.003,1\n", "time_s goes backwards at line 6"),
    (HEADER + "time_s,thrust_N\n" + "".join(f"{k * 0.02},{k % 3}\n" for k in range(200)),
     "sampled at 50 Hz; femstudy accepts 100 Hz to 10 kHz"),
    (HEADER + "time_s,thrust_N\n" + "".join(f"{k * 0.001},5\n" for k in range(100)), "thrust_N is constant"),
    (HEADER + "time_s,thrust_N\n" + "".join(f"{k * 0.001},{k}\n" for k in range(20)),
     "shorter than one spindle revolution (0.04 s at 1500 rpm)"),
    ("# feed_mm_s = 1.5\ntime_s,thrust_N\n0,1\n", "has no spindle_rpm"),
    ("# feed_mm_s = -1.5\n# spindle_rpm = 1500\ntime_s,thrust_N\n0,1\n",
     "rec.csv, line 1: feed_mm_s: Input should be greater than 0, got -1.5"),
    ("# feed_mm_s = 1.5\n# spindle_rpm = 1500\n# drill_diameter_mm = \"big\"\ntime_s,thrust_N\n0,1\n",
     "rec.csv, line 3: drill_diameter_mm: Input should be a valid number, unable to parse string as a number, "
     "got \"big\""),
    ("# feed_mm_per_s = 1.5\n# spindle_rpm = 1500\ntime_s,thrust_N\n0,1\n",
     "has no feed_mm_s (line 1 has feed_mm_per_s: a misspelling?)"),
    ("# feed_mm_s = 1.5\n# spindle_rpm = fast\ntime_s,thrust_N\n0,1\n",
     "line 2: '# spindle_rpm = fast' is not 'key = value' with a TOML value"),
    (HEADER + "# samples = 3000000000\ntime_s,thrust_N\n0,1\n", "the header claims 3,000,000,000 samples"),
    (HEADER + "# samples = 500\ntime_s,thrust_N\n" + rows(torque=False),
     "header says samples = 500 but the file has 400"),
    ("\x00\x01binary", "is not a text (UTF-8) CSV file"),
]


@pytest.mark.parametrize("text, message", BAD, ids=[m[:40] for _, m in BAD])
def test_bad_recordings_give_one_clear_sentence(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(UserError) as info:
        read_recording(path)
    assert message in str(info.value)
    assert "\n" not in str(info.value)


def test_missing_file_and_folder_and_non_utf8(tmp_path):
    with pytest.raises(UserError, match="does not exist"):
        read_recording(tmp_path / "nope.csv")
    with pytest.raises(UserError, match="is a folder; give one recording file"):
        read_recording(tmp_path)
    (tmp_path / "latin.csv").write_bytes(HEADER.encode() + b"# specimen = \"f\xe9mur\"\ntime_s,thrust_N\n")
    with pytest.raises(UserError, match="not a text \\(UTF-8\\) CSV file"):
        read_recording(tmp_path / "latin.csv")


def test_clean_synthetic_recording_reads_back_without_notes(tmp_path):
    rec = synthesize(2.0, 1000, effects=Effects.none(), sample_rate_hz=500)
    write_recording(tmp_path / "c.csv", rec, torque_unit="Nm")
    back = read_recording(tmp_path / "c.csv")
    assert back.sample_rate_hz == pytest.approx(500)
    np.testing.assert_allclose(back.torque_Nmm, rec.torque_Nmm, rtol=1e-5, atol=1e-6)


def _stamped(tmp_path, stamps, fmt="%.6f"):
    body = "".join(f"{fmt % t},{1 + (k % 7)},{2 + k % 5}\n" for k, t in enumerate(stamps))
    path = tmp_path / "rec.csv"
    path.write_text(HEADER + "time_s,thrust_N,torque_Nmm\n" + body)
    return read_recording(path)


def test_repeated_stamps_are_merged_into_the_mean_of_their_rows(tmp_path):
    """A logger whose clock is coarser than its sampling (1 ms at 2 kHz) stamps two rows alike; a
    buffer written twice repeats a row. Each set of rows sharing a stamp becomes their mean."""
    stamps = (np.arange(400) // 2) * 1e-3                           # 2 kHz, stamped to the millisecond
    rec = _stamped(tmp_path, stamps)
    assert rec.time_s.size == 200 and np.all(np.diff(rec.time_s) > 0)
    assert rec.thrust_N[0] == pytest.approx((1 + 2) / 2)           # rows 0 and 1: thrust 1 and 2
    assert any("200 repeated time stamp(s) (400 rows) were merged" in n for n in rec.notes)


def test_clock_jitter_out_of_order_stamps_are_ordered_a_jump_back_is_refused(tmp_path):
    t = np.arange(400) * 1e-3
    t[50], t[51] = 0.0502, 0.0498                                   # 0.4 ms apart, written in the wrong order
    rec = _stamped(tmp_path, t)
    assert np.all(np.diff(rec.time_s) > 0) and rec.time_s.size == 400
    assert any("1 time stamp(s) out of order" in n for n in rec.notes)
    t = np.arange(400) * 1e-3
    t[200:] -= 0.05                                                 # 50 samples back: two records spliced
    with pytest.raises(UserError, match="goes backwards"):
        _stamped(tmp_path, t)


def test_epoch_stamps_count_from_the_first_sample(tmp_path):
    """Unix time (1.7e9 s + t) in float64 reads as t, with the origin kept in the metadata."""
    t = np.arange(400) * 1e-3
    plain = _stamped(tmp_path, t)
    epoch = _stamped(tmp_path, 1.7e9 + 12.345 + t)
    np.testing.assert_allclose(epoch.time_s, plain.time_s, atol=2e-6)
    assert epoch.metadata["time_origin_s"] == pytest.approx(1.7e9 + 12.345)
    assert any("an absolute clock" in n for n in epoch.notes) and plain.notes == ()

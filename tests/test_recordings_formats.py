"""Recordings as acquisition software, MATLAB and Excel write them: each format written,
read back and compared with the recording it came from; files written by hand the way
Kistler, LabVIEW, MATLAB and a European Excel write them; the column map; bad inputs."""

import numpy as np
import pytest

from femstudy.errors import UserError
from femstudy.recordings import Effects, read_recording, synthesize, write_recording
from femstudy.recordings.formats.text import TextStyle
from femstudy.recordings.formats import registry
from femstudy.recordings import units

FORMAT_SUFFIXES = {name: w.suffix for name, w in registry.writers().items()}

#: what each format keeps: (relative tolerance of time, of loads); text writes 9 and 6
#: significant digits, Excel 15, TDMS and MATLAB the float64 itself
PRECISION = {"text": (5e-9, 5e-6), "xlsx": (1e-14, 1e-14), "binary": (0.0, 0.0)}


def precision(fmt: str):
    return PRECISION["binary" if fmt in ("tdms", "mat", "mat73") else "xlsx" if fmt == "xlsx" else "text"]


@pytest.fixture(scope="module")
def original():
    """A short synthetic recording (3 s at 500 Hz) with every optional column but fx/fy."""
    return synthesize(1.5, 1500, cortex_mm=3.0, approach_s=0.5, tail_s=0.5, sample_rate_hz=500, seed=1,
                      depth_column=True, metadata={"outlier": False, "outlier_reason": "", "replicate": 3})


def assert_same_recording(back, rec, time_rtol, load_rtol):
    np.testing.assert_allclose(back.time_s, rec.time_s, rtol=time_rtol, atol=time_rtol)
    for name in ("thrust_N", "torque_Nmm", "depth_mm"):
        want, got = getattr(rec, name), getattr(back, name)
        np.testing.assert_allclose(got, want, rtol=load_rtol, atol=load_rtol * np.max(np.abs(want)), err_msg=name)


def test_synth_offers_every_format():
    from femstudy.cli import build_parser

    synth = build_parser()._subparsers._group_actions[0].choices["synth"]
    offered = next(a.choices for a in synth._actions if a.dest == "format")
    assert set(offered) == set(FORMAT_SUFFIXES)


@pytest.mark.parametrize("fmt", list(FORMAT_SUFFIXES))
def test_every_format_reads_back_the_same_samples_and_metadata(tmp_path, original, fmt):
    path = tmp_path / f"rec{FORMAT_SUFFIXES[fmt]}"
    write_recording(path, original, format=fmt)
    back = read_recording(path)
    assert_same_recording(back, original, *precision(fmt))
    assert back.notes == ()  # written in s, N, N·mm: nothing converted
    for key, value in original.metadata.items():
        if isinstance(value, float):
            assert back.metadata[key] == pytest.approx(value, rel=max(precision(fmt)[0], 1e-15)), key
        else:
            assert back.metadata[key] == value, key  # MATLAB's 0/1 equal False/True
    assert back.metadata["samples"] == original.time_s.size


@pytest.mark.parametrize("units, column, note", [
    ({"time_unit": "ms"}, "time_ms", "time_ms converted from ms to s (x0.001)"),
    ({"time_unit": "min"}, "time_min", "time_min converted from min to s (x60)"),
    ({"force_unit": "kN"}, "thrust_kN", "thrust_kN converted from kN to N (x1000)"),
    ({"force_unit": "lbf"}, "thrust_lbf", "thrust_lbf converted from lbf to N (x4.44822)"),
    ({"torque_unit": "N·m"}, "torque_Nm", "torque_Nm converted from Nm to N·mm (x1000)"),
    ({"torque_unit": "lbf*in"}, "torque_lbfin", "torque_lbfin converted from lbfin to N·mm (x112.985)"),
    ({"torque_unit": "ozf*in"}, "torque_ozfin", "torque_ozfin converted from ozfin to N·mm (x7.06155)"),
])
def test_units_are_converted_through_pint(tmp_path, original, units, column, note):
    path = tmp_path / "rec.csv"
    write_recording(path, original, **{"torque_unit": "Nmm", **units})
    assert column in path.read_text().splitlines()[len(original.metadata) + 1]
    back = read_recording(path)
    assert note in back.notes
    assert_same_recording(back, original, 1e-8, 1e-5)


@pytest.mark.parametrize("quantity", sorted(units.QUANTITY_UNITS))
def test_the_si_factors_kept_without_pint_are_pints_own(quantity):
    ureg = units.registry()
    target = units.QUANTITY_UNITS[quantity][0]
    kept = [unit for own, unit in units.SI_FACTORS if own == target]
    assert kept
    for unit in kept:
        assert units.SI_FACTORS[target, unit] == pytest.approx(
            float(ureg.Quantity(1.0, units.parse_unit(unit)).to(target).magnitude), rel=1e-14)
        assert units.factor_to_solver(unit, quantity, "column") == units.SI_FACTORS[target, unit]


def test_a_recording_in_newton_metres_and_milliseconds_is_read_without_building_pints_registry(tmp_path, original):
    write_recording(tmp_path / "rec.csv", original, "N·m", time_unit="ms")
    units.registry.cache_clear()
    back = read_recording(tmp_path / "rec.csv")
    assert units.registry.cache_info().currsize == 0
    assert "torque_Nm converted from Nm to N·mm (x1000)" in back.notes
    assert_same_recording(back, original, 1e-8, 1e-5)


def test_units_in_a_binary_format_are_converted_too(tmp_path, original):
    write_recording(tmp_path / "rec.tdms", original, "N*m", time_unit="ms", force_unit="kN")
    back = read_recording(tmp_path / "rec.tdms")
    assert set(back.notes) == {"Time converted from ms to s (x0.001)", "Fz converted from kN to N (x1000)",
                               "Mz converted from N*m to N·mm (x1000)"}
    assert_same_recording(back, original, 1e-15, 1e-15)


def test_text_variants_give_the_same_numbers_bit_for_bit(tmp_path, original):
    """A delimiter, a decimal comma, a byte-order mark or CRLF changes nothing read."""
    write_recording(tmp_path / "plain.csv", original)
    plain = read_recording(tmp_path / "plain.csv")
    for k, style in enumerate([TextStyle(";"), TextStyle("\t"), TextStyle(";", ","), TextStyle("\t", ","),
                               TextStyle(bom=True), TextStyle(newline="\r\n"),
                               TextStyle(";", ",", bom=True, newline="\r\n")]):
        write_recording(tmp_path / f"{k}.csv", original, format=style)
        raw = (tmp_path / f"{k}.csv").read_bytes()
        assert raw.startswith(b"\xef\xbb\xbf") == style.bom and (b"\r\n" in raw) == (style.newline == "\r\n")
        back = read_recording(tmp_path / f"{k}.csv")
        for name in ("time_s", "thrust_N", "torque_Nmm", "depth_mm"):
            assert np.array_equal(getattr(back, name), getattr(plain, name)), (style, name)
        assert back.metadata == plain.metadata


# -- files as other software writes them --------------------------------------------------------

def signal(n=600, rate=1000.0):
    t = np.arange(n) / rate
    thrust = 20 * np.clip((t - 0.1) / 0.2, 0, 1) + 0.1 * np.sin(40 * t)
    return t, thrust, 1.5 * thrust  # torque in N·mm


def test_kistler_like_text_export_with_header_block_and_units_row(tmp_path):
    """Laid out like Kistler BioWare's .txt export (DynoWare's sibling): a header block of
    'name<TAB>value' lines, the channel names, a units row, tab-separated numbers; CRLF."""
    t, thrust, torque = signal()
    lines = ["BioWare Version 5.2.1.3 Export", "Device:\tKistler 9345B", f"Samples (#):\t{t.size}",
             "Rate (Hz):\t1000.000000", "File Information", "Date\tOct 22, 2014  12:05:31", "Name\t",
             "Description\tbovine femur 3, hole 2", "feed_mm_s\t1.5", "spindle_rpm:\t1500",
             "abs time (s)\tFx\tFz\tMz", "\tN\tN\tN·m"]
    fx = 0.01 + 0.002 * np.sin(7 * t)  # a lateral force that varies (a constant channel is refused as dead)
    lines += [f"{a:.6f}\t{x:.6f}\t{b:.6f}\t{c / 1000:.9f}" for a, x, b, c in zip(t, fx, thrust, torque)]
    path = tmp_path / "kistler.txt"
    path.write_bytes("\r\n".join(lines).encode() + b"\r\n")
    rec = read_recording(path)
    np.testing.assert_allclose(rec.thrust_N, thrust, atol=1e-6)
    np.testing.assert_allclose(rec.torque_Nmm, torque, atol=1e-5)
    np.testing.assert_allclose(rec.time_s, t, atol=1e-9)
    np.testing.assert_allclose(rec.fx_N, fx, atol=1e-6)
    assert (rec.feed_mm_s, rec.spindle_rpm) == (1.5, 1500)
    assert rec.metadata["Description"] == "bovine femur 3, hole 2" and "Name" not in rec.metadata
    assert rec.notes == ("Mz converted from N·m to N·mm (x1000)",)


def test_european_export_semicolons_decimal_comma_bom_bracketed_units(tmp_path):
    t, thrust, torque = signal()
    text = "# feed_mm_s = 1.5\r\n# spindle_rpm = 1500\r\nZeit [ms];Fz [kN];Mz (N·m)\r\n"
    text += "".join(f"{a * 1000:.3f};{b / 1000:.9f};{c / 1000:.9f}\r\n".replace(".", ",")
                    for a, b, c in zip(t, thrust, torque))
    (tmp_path / "eu.csv").write_bytes(b"\xef\xbb\xbf" + text.encode())
    rec = read_recording(tmp_path / "eu.csv")
    np.testing.assert_allclose(rec.thrust_N, thrust, atol=1e-6)
    np.testing.assert_allclose(rec.torque_Nmm, torque, atol=1e-6)
    np.testing.assert_allclose(rec.time_s, t, atol=1e-9)


def test_excel_unicode_text_utf16_tab_separated(tmp_path):
    t, thrust, torque = signal()
    text = "feed_mm_s\t1,5\nspindle_rpm\t1500\nZeit [s]\tFz [N]\tMz [N·mm]\n"
    text += "".join(f"{a:.4f}\t{b:.6f}\t{c:.6f}\n".replace(".", ",") for a, b, c in zip(t, thrust, torque))
    (tmp_path / "unicode.txt").write_bytes(text.encode("utf-16"))  # with its byte-order mark
    rec = read_recording(tmp_path / "unicode.txt")
    np.testing.assert_allclose(rec.torque_Nmm, torque, atol=1e-6)
    assert rec.feed_mm_s == 1.5  # a decimal comma in the header block too


def test_column_map_names_columns_and_units_from_command_line_and_header(tmp_path):
    t, thrust, torque = signal()
    body = "".join(f"{a * 1000:.3f}\t{b:.6f}\t{c:.6f}\n" for a, b, c in zip(t, thrust, torque))
    path = tmp_path / "lab.tsv"
    path.write_text("# feed_mm_s = 1.5\n# spindle_rpm = 1500\nZeitpunkt\tKraft\tMoment\n" + body)
    with pytest.raises(UserError, match="has no time_s column \\(seconds\\), nor another time column"):
        read_recording(path)
    rec = read_recording(path, columns="time=Zeitpunkt[ms], thrust=Kraft[N], torque=Moment[N*mm]")
    np.testing.assert_allclose(rec.time_s, t, atol=1e-9)
    np.testing.assert_allclose(rec.thrust_N, thrust, atol=1e-6)
    # the same map in the header; the command line wins where both name a quantity
    path.write_text('# feed_mm_s = 1.5\n# spindle_rpm = 1500\n'
                    '# columns = "time=Zeitpunkt[ms],thrust=Kraft[N],torque=Moment[N*mm]"\n'
                    'Zeitpunkt\tKraft\tMoment\n' + body)
    assert np.array_equal(read_recording(path).torque_Nmm, rec.torque_Nmm)
    swapped = read_recording(path, columns="thrust=Moment[N]")
    np.testing.assert_allclose(swapped.thrust_N, torque, atol=1e-6)
    assert "--columns thrust=Moment overrides the file's thrust=Kraft" in swapped.notes


def test_tdms_waveform_channels_without_a_time_channel(tmp_path):
    """DAQmx logging: one group, channels with unit_string and waveform timing, no time channel."""
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    t, thrust, torque = signal()
    timing = {"wf_increment": 0.001, "wf_start_offset": 0.0, "wf_xunit_string": "s"}
    with TdmsWriter(tmp_path / "daq.tdms") as writer:
        writer.write_segment([RootObject(properties={"name": "hole 2", "feed_mm_s": 1.5}),
                              GroupObject("Dynamometer", properties={"spindle_rpm": 1500.0}),
                              ChannelObject("Dynamometer", "Fz", thrust / 1000, {"unit_string": "kN", **timing}),
                              ChannelObject("Dynamometer", "Mz", torque, {"unit_string": "N·mm", **timing})])
    rec = read_recording(tmp_path / "daq.tdms")
    np.testing.assert_allclose(rec.time_s, t, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(rec.thrust_N, thrust, rtol=1e-12)
    assert rec.metadata["name"] == "hole 2" and rec.spindle_rpm == 1500


def test_matlab_vectors_with_a_units_struct_and_scalar_metadata(tmp_path):
    import scipy.io

    t, thrust, torque = signal()
    scipy.io.savemat(tmp_path / "run.mat", {"t": t, "Fz": thrust, "Mz": torque / 1000, "feed_mm_s": 1.5,
                                            "spindle_rpm": 1500, "specimen": "femur 3", "fs": 1000.0,
                                            "units": {"t": "s", "Fz": "N", "Mz": "N*m"}})
    rec = read_recording(tmp_path / "run.mat")
    np.testing.assert_allclose(rec.torque_Nmm, torque, rtol=1e-12)
    assert rec.metadata["specimen"] == "femur 3" and rec.metadata["fs"] == 1000.0


def test_xlsx_with_header_block_units_row_and_no_metadata_sheet(tmp_path):
    import openpyxl

    t, thrust, torque = signal()
    book = openpyxl.Workbook()
    sheet = book.active
    sheet.title = "Messung"
    for row in (["feed_mm_s", 1.5], ["spindle_rpm", 1500], ["specimen", "bovine femur 3"], [],
                ["Zeit", "Fz", "Mz"], ["ms", "kN", "N·m"]):
        sheet.append(row)
    for a, b, c in zip(t, thrust, torque):
        sheet.append([a * 1000, b / 1000, c / 1000])
    book.save(tmp_path / "run.xlsx")
    rec = read_recording(tmp_path / "run.xlsx")
    np.testing.assert_allclose(rec.thrust_N, thrust, rtol=1e-12)
    np.testing.assert_allclose(rec.time_s, t, rtol=1e-12, atol=1e-15)
    assert rec.metadata["specimen"] == "bovine femur 3" and rec.feed_mm_s == 1.5


# -- bad inputs -----------------------------------------------------------------------------

HEADER = "# feed_mm_s = 1.5\n# spindle_rpm = 1500\n"


def csv_body(n=300):
    t, thrust, torque = signal(n)
    return "".join(f"{a:.6g},{b:.6g},{c:.6g}\n" for a, b, c in zip(t, thrust, torque))


@pytest.mark.parametrize("columns, message", [
    ("trust=Fz", "--columns: unknown quantity 'trust'; use time, thrust, torque, depth, fx, fy"),
    ("thrust", "--columns: 'thrust' is not quantity=column (e.g. thrust=Fz)"),
    ("thrust=Kraft", "has no column 'Kraft' for thrust; its columns are: time_s, thrust_N, torque_Nmm"),
    ("thrust=thrust_N[kN]", "column 'thrust_N' is in N but the column map says kN"),
    ("thrust=torque_Nmm", "column 'torque_Nmm' is in Nmm (a torque); thrust needs a force unit"),
])
def test_bad_column_maps(tmp_path, columns, message):
    (tmp_path / "r.csv").write_text(HEADER + "time_s,thrust_N,torque_Nmm\n" + csv_body())
    with pytest.raises(UserError) as info:
        read_recording(tmp_path / "r.csv", columns=columns)
    assert message in str(info.value)


def test_bad_binary_and_spreadsheet_files(tmp_path):
    import openpyxl
    import scipy.io
    from nptdms import ChannelObject, GroupObject, RootObject, TdmsWriter

    t, thrust, torque = signal()
    with TdmsWriter(tmp_path / "no_thrust.tdms") as writer:
        writer.write_segment([RootObject(properties={"feed_mm_s": 1.5, "spindle_rpm": 1500.0}), GroupObject("g"),
                              ChannelObject("g", "Time", t, {"unit_string": "s"}),
                              ChannelObject("g", "Mz", torque, {"unit_string": "N·mm"})])
    with TdmsWriter(tmp_path / "ragged.tdms") as writer:
        writer.write_segment([RootObject(properties={"feed_mm_s": 1.5, "spindle_rpm": 1500.0}), GroupObject("g"),
                              ChannelObject("g", "Time", t, {"unit_string": "s"}),
                              ChannelObject("g", "Fz", thrust[:-5], {"unit_string": "N"})])
    scipy.io.savemat(tmp_path / "scalars.mat", {"feed_mm_s": 1.5, "spindle_rpm": 1500})
    book = openpyxl.Workbook()
    book.active.append(["time [s]", "thrust [N]"])
    book.active.append(["zero", "one"])
    book.save(tmp_path / "words.xlsx")
    book = openpyxl.Workbook()
    for row in (["feed_mm_s", 1.5], ["spindle_rpm", 1500], ["time [s]", "thrust [N]"], [0.0, 1.0], [0.001, None],
                [0.002, 3.0]):
        book.active.append(row)
    book.save(tmp_path / "hole.xlsx")
    scipy.io.savemat(tmp_path / "matrix.mat", {"data": np.column_stack([t, thrust, torque]), "feed_mm_s": 1.5})
    (tmp_path / "fake.xlsx").write_text(HEADER + "time_s,thrust_N\n0,1\n")
    (tmp_path / "fake.tdms").write_text(HEADER + "time_s,thrust_N\n0,1\n")
    (tmp_path / "garbage.mat").write_bytes(b"MATLAB 5.0 MAT-file" + bytes(200))
    (tmp_path / "zip.xlsx").write_bytes(b"PK\x03\x04" + bytes(100))
    expected = {
        "no_thrust.tdms": "has no thrust_N channel (newtons), nor another thrust channel (fz, thrust) with a unit; "
                          "its channels are: Time, Mz",
        "ragged.tdms": "its channels differ in length ('Time' 600 samples, 'Fz' 595 samples)",
        "scalars.mat": "(MATLAB) has no numeric vector variables; femstudy needs one per column, e.g. t, Fz and Mz "
                       "(variables found: feed_mm_s, spindle_rpm)",
        "matrix.mat": "(variables found: data (a 600 x 3 matrix), feed_mm_s); save the columns of data as vectors",
        "words.xlsx": "sheet 'Sheet' has no row of numbers",
        "hole.xlsx": "hole.xlsx, row 5: an empty cell in column 'thrust [N]' is not a number",
        "fake.xlsx": "has a .xlsx name but is not an Excel .xlsx workbook",
        "fake.tdms": "has a .tdms name but is not a TDMS file",
        "garbage.mat": "is not a readable MATLAB .mat file",
        "zip.xlsx": "is not a readable Excel .xlsx workbook",
    }
    for name, message in expected.items():
        with pytest.raises(UserError) as info:
            read_recording(tmp_path / name, {"feed_mm_s": 1.5, "spindle_rpm": 1500})
        assert message in str(info.value), name
        assert "\n" not in str(info.value)


def test_metadata_errors_name_the_place_in_each_format(tmp_path, original):
    from dataclasses import replace

    bad = replace(original, metadata={**original.metadata, "feed_mm_s": -1.5})
    places = {"csv": "line 1", "dynoware": "line 4", "tdms": "file property feed_mm_s",
              "mat": "variable metadata.feed_mm_s", "xlsx": "sheet 'metadata' row 1"}
    for fmt, place in places.items():
        path = tmp_path / f"bad{FORMAT_SUFFIXES[fmt]}"
        write_recording(path, bad, format=fmt)
        with pytest.raises(UserError) as info:
            read_recording(path)
        assert str(info.value) == f"recording {path.name}, {place}: feed_mm_s: Input should be greater than 0, got -1.5"


def test_unreadable_file_and_folder(tmp_path, monkeypatch):
    from pathlib import Path

    path = tmp_path / "r.csv"
    path.write_text(HEADER + "time_s,thrust_N\n" + csv_body())

    def refuse(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(Path, "open", refuse)
    with pytest.raises(UserError, match=r"cannot read recording .*r.csv: Permission denied"):
        read_recording(path)
    monkeypatch.undo()
    (tmp_path / "latin1.csv").write_bytes((HEADER + "time_s,thrust_N\n" + csv_body()).encode() + b"# K\xe9\n1,2\n")
    with pytest.raises(UserError, match="latin1.csv is not a text \\(UTF-8\\) CSV file"):
        read_recording(tmp_path / "latin1.csv")  # the bad byte after the first rows
    (tmp_path / "folder.csv").mkdir()
    with pytest.raises(UserError, match="folder.csv is a folder; give one recording file"):
        read_recording(tmp_path / "folder.csv")


def test_nan_after_conversion_names_the_column_as_written(tmp_path):
    body = csv_body().splitlines()
    body[40] = body[40].split(",")[0] + ",nan," + body[40].split(",")[2]
    (tmp_path / "r.csv").write_text(HEADER + "time_ms,thrust_kN,torque_Nm\n" + "\n".join(body) + "\n")
    with pytest.raises(UserError, match="recording r.csv: thrust_kN is nan at line 44"):
        read_recording(tmp_path / "r.csv")


def test_clean_recordings_survive_every_format(tmp_path):
    rec = synthesize(2.0, 1000, effects=Effects.none(), sample_rate_hz=200, approach_s=0.3, tail_s=0.3,
                     cortex_mm=2.0)
    for fmt in FORMAT_SUFFIXES:
        write_recording(tmp_path / f"c{FORMAT_SUFFIXES[fmt]}", rec, format=fmt)
        back = read_recording(tmp_path / f"c{FORMAT_SUFFIXES[fmt]}")
        np.testing.assert_allclose(back.thrust_N, rec.thrust_N, rtol=1e-5, atol=1e-9, err_msg=fmt)


def test_synth_writes_a_recording_and_a_data_set_in_another_format(tmp_path):
    from femstudy import cli
    from femstudy.recordings.workflow import recording_paths

    assert cli.main(["synth", "--out", str(tmp_path / "one"), "--format", "xlsx", "--time-unit", "ms",
                     "--force-unit", "kN", "--torque-unit", "N*m", "--rate-hz", "200", "--quiet"]) == 0
    rec = read_recording(tmp_path / "one")
    assert "Fz converted from kN to N (x1000)" not in rec.notes  # .xlsx names it 'thrust [kN]'
    assert "thrust [kN] converted from kN to N (x1000)" in rec.notes
    assert cli.main(["synth", "--dataset", str(tmp_path / "set"), "--replicates", "1", "--outliers", "0",
                     "--rate-hz", "200", "--format", "mat", "--quiet"]) == 0
    found = recording_paths([tmp_path / "set" / "calibration"], "RUNS")
    assert len(found) == 5 and all(p.suffix == ".mat" for p in found)
    assert "calibration/f1_N1000_r01.mat" in (tmp_path / "set" / "truth.csv").read_text()
    assert read_recording(found[0]).metadata["role"] == "calibration"


PREFIXES = [b"", b"TDSm", b"PK\x03\x04", b"MATLAB 5.0 MAT-file", b"\x89HDF\r\n\x1a\n", b"\xef\xbb\xbf", b"\xff\xfe"]


def test_random_bytes_in_every_format_are_refused_in_one_sentence(tmp_path):
    """Damaged files of every kind: a UserError, never a traceback."""
    rng = np.random.default_rng(7)
    for k in range(150):
        prefix = PREFIXES[k % len(PREFIXES)]
        suffix = (".csv", ".tdms", ".xlsx", ".mat", ".txt")[k % 5]
        path = tmp_path / f"r{k}{suffix}"
        path.write_bytes(prefix + rng.integers(0, 256, int(rng.integers(0, 3000)), dtype=np.uint8).tobytes())
        with pytest.raises(UserError) as info:
            read_recording(path, {"feed_mm_s": 1.5, "spindle_rpm": 1500})
        assert "\n" not in str(info.value)

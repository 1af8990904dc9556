"""Measured data, both readers: errors are one line naming file, column and row; --drop-bad drops and counts;
the split belongs to the data."""

import dataclasses
import itertools

import numpy as np
import pytest
from simulator import Truth, write_set

from tension_zones.calibration import DataError, read_csv, read_opencr
from tension_zones.calibration._data import servo_map_from_labels
from tension_zones.cli import main


@pytest.fixture(scope="module")
def good(tmp_path_factory):
    folder = tmp_path_factory.mktemp("data")
    csv, dj = write_set(folder, "ok", Truth(), 60, seed=0)
    return csv.read_text().splitlines(), dj


def edit(lines, row, col, value):
    """Lines with data row ``row`` (1-based), column ``col`` set to ``value``."""
    header = lines[0].split(",")
    out = list(lines)
    cells = out[row].split(",")
    cells[header.index(col)] = value
    out[row] = ",".join(cells)
    return out


def write(tmp_path, lines):
    p = tmp_path / "d.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


def test_good_file_loads(good):
    lines, _ = good
    ds = read_csv(write_tmp(lines), 3, 20.0)
    assert ds.n_samples == 60 and ds.n_wires == 3 and ds.dropped == ()


_WRITTEN = itertools.count(1)  # numbers the files write_tmp writes


def write_tmp(lines):
    import tempfile
    from pathlib import Path

    p = Path(tempfile.mkdtemp()) / f"d{next(_WRITTEN)}.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.mark.parametrize(
    "mutate, needle",
    [
        (lambda L: edit(L, 7, "px", "nan"), "column 'px', row 7"),
        (lambda L: edit(L, 12, "q2", "inf"), "column 'q2', row 12"),
        (lambda L: edit(L, 5, "fz", "abc"), "column 'fz', row 5"),
        (lambda L: edit(L, 9, "sample", "7"), "column 'sample', row 9"),
        (lambda L: edit(L, 3, "q1", "25.0"), "column 'q1', row 3"),
        (lambda L: edit(L, 4, "rx", "4.0"), "column 'rx', row 4"),
        (lambda L: edit(L, 6, "fx", "1e5"), "column 'fx', row 6"),
    ],
)
def test_bad_values_name_column_and_row(good, mutate, needle):
    lines, _ = good
    with pytest.raises(DataError, match=needle.replace("(", r"\(")) as e:
        read_csv(write_tmp(mutate(lines)), 3, 20.0)
    assert "\n" not in str(e.value)


def test_missing_column(good):
    lines, _ = good
    header = lines[0].split(",")
    drop = header.index("py")
    cut = [",".join(c for i, c in enumerate(l.split(",")) if i != drop) for l in lines]
    with pytest.raises(DataError, match="missing column 'py'"):
        read_csv(write_tmp(cut), 3, 20.0)


def test_wire_count_disagrees_with_design(good):
    lines, _ = good
    with pytest.raises(DataError, match="the design has 4 wires but .* has 3 wire columns"):
        read_csv(write_tmp(lines), 4, 20.0)


def test_drop_bad_drops_isolated_rows_and_counts_them(good):
    lines, _ = good
    bad = edit(edit(lines, 7, "px", "nan"), 30, "sample", "3")
    ds = read_csv(write_tmp(bad), 3, 20.0, drop_bad=True)
    assert ds.n_samples == 58
    assert [d["row"] for d in ds.dropped] == [7, 30]
    assert {d["column"] for d in ds.dropped} == {"px", "sample"}
    assert 6 not in ds.sample and ds.sample.tolist() == sorted(ds.sample.tolist())


def test_drop_bad_refuses_runs_and_many(good):
    lines, _ = good
    run = edit(edit(edit(lines, 7, "px", "nan"), 8, "py", "nan"), 9, "pz", "nan")
    with pytest.raises(DataError, match="not isolated"):
        read_csv(write_tmp(run), 3, 20.0, drop_bad=True)
    many = lines
    for r in range(2, 60, 6):
        many = edit(many, r, "pz", "nan")
    with pytest.raises(DataError, match="not isolated"):
        read_csv(write_tmp(many), 3, 20.0, drop_bad=True)


def test_cli_errors_are_one_line(good, tmp_path, capsys):
    lines, dj = good
    bad = write(tmp_path, edit(lines, 7, "px", "nan"))
    assert main(["calibrate", str(bad), "--design", str(dj), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "column 'px', row 7" in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()
    assert main(["calibrate", str(tmp_path / "nope.csv"), "--design", str(dj), "--out", str(tmp_path / "o")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["calibrate", str(bad), "--design", str(dj), "--out", str(tmp_path / "o"), "--holdout", "1.5"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_samples_out_of_order(good):
    lines, _ = good
    swapped = list(lines)
    swapped[10], swapped[11] = swapped[11], swapped[10]
    with pytest.raises(DataError, match="column 'sample', row 11: samples must be in acquisition order"):
        read_csv(write_tmp(swapped), 3, 20.0)


def test_split_in_acquisition_order(good):
    lines, _ = good
    ds = read_csv(write_tmp(lines), 3, 20.0)
    train, held = ds.split(0.25)
    assert train.sum() == 45 and np.all(train[:45]) and np.all(held[45:])
    with pytest.raises(DataError, match="holdout"):
        ds.split(0.0)


@pytest.mark.parametrize(
    "edit_text, needle",
    [
        (lambda s: "\ufeff" + s, None),  # a byte-order mark is handled
        (lambda s: s.replace(",", ";"), None),  # so is a semicolon-separated file
        (lambda s: s.replace(",", "\t"), None),  # and a tab-separated one
        (lambda s: s.replace(",", ";").replace(".", ","), "decimal comma"),
        (lambda s: s.replace("fx", "force_x", 1), "missing column 'fx'"),
        (lambda s: "sample q1 q2\n1 2 3\n", "single column"),
        (lambda s: "", "empty"),
        (lambda s: s.split("\n")[0] + "\n", "no data rows"),
    ],
)
def test_formats_handled_or_named(good, edit_text, needle):
    lines, _ = good
    p = write_tmp(["x"])
    p.write_bytes(edit_text("\n".join(lines) + "\n").encode("utf-8"))
    if needle is None:
        assert read_csv(p, 3, 20.0).n_samples == 60
    else:
        with pytest.raises(DataError, match=needle) as e:
            read_csv(p, 3, 20.0)
        assert "\n" not in str(e.value)


def test_paths_and_the_wrong_reader_are_named(good, tmp_path):
    with pytest.raises(DataError, match="is a folder, not a file"):
        read_csv(tmp_path, 3, 20.0)
    with pytest.raises(DataError, match="does not exist"):
        read_csv(tmp_path / "nope.csv", 3, 20.0)
    with pytest.raises(DataError, match="looks like an OpenCR recording .* use --format opencr"):
        read_csv(write_ocr(tmp_path), 3, 20.0)
    lines, _ = good
    with pytest.raises(DataError, match="looks like a tension_zones/MODEL.md measurement set .* use --format model"):
        read_opencr(write_tmp(lines))
    (tmp_path / "bin.csv").write_bytes(b"\xff\xfe\x00\x01garbage")
    with pytest.raises(DataError, match="not UTF-8 text"):
        read_csv(tmp_path / "bin.csv", 3, 20.0)


def test_drop_bad_drops_blank_and_non_numeric_cells_and_short_rows(good):
    lines, _ = good
    bad = edit(edit(lines, 10, "py", ""), 20, "q3", "n/a")
    bad[40] = ",".join(bad[40].split(",")[:5])
    with pytest.raises(DataError, match=r"column 'py', row 10 \(sample 9\): is blank"):
        read_csv(write_tmp(bad), 3, 20.0)
    ds = read_csv(write_tmp(bad), 3, 20.0, drop_bad=True)
    assert [d["row"] for d in ds.dropped] == [10, 20, 40] and ds.n_samples == 57


# ---------------------------------------------------------------------------------------------
# the OpenCR reader
# ---------------------------------------------------------------------------------------------
HEADER = "timestamp,pattern_label,servo_2_mm,servo_1_mm,servo_3_mm,tip_x,tip_y,tip_z"
ROWS = [
    "1.0,rep1_tendon0_id2_pull,0.5,-1.0,-1.0,1.0,2.0,188.0",
    "1.5,rep1_tendon0_id2_pull,1.0,-2.0,-2.0,3.0,2.0,187.0",
    "2.0,rep1_tendon1_id1_pull,-1.0,0.5,-1.0,0.0,-3.0,187.5",
    "2.5,rep1_tendon2_id3_pull_hold,-1.0,-1.0,0.25,-1.0,1.0,187.9",
]


def write_ocr(tmp_path, rows=ROWS, header=HEADER, name="ocr.csv"):
    p = tmp_path / name
    p.write_text("\n".join([header, *rows]) + "\n")
    return p


def test_opencr_mapping_sign_order_and_groups(tmp_path):
    d = read_opencr(write_ocr(tmp_path), n_wires=3)
    assert d.servo_ids == (2, 1, 3) and d.frame == "tracker" and not d.f.any()
    # tendon order and tension_zones/MODEL.md sign (negative = pulled in)
    np.testing.assert_allclose(d.q[0], [-0.5, 1.0, 1.0])
    np.testing.assert_allclose(d.q[3], [1.0, 1.0, -0.25])
    np.testing.assert_allclose(d.p[1], [3.0, 2.0, 187.0])
    assert d.groups[3] == "rep1_tendon2_id3_pull"
    # an explicit mapping reorders the columns
    d2 = read_opencr(write_ocr(tmp_path), servo_ids=[1, 2, 3])
    np.testing.assert_allclose(d2.q[:, 0], d.q[:, 1])


@pytest.mark.parametrize(
    "rows, header, kw, message",
    [
        (ROWS, HEADER.replace("tip_y", "tip_q"), {}, "missing column 'tip_y'"),
        (
            [ROWS[0], ROWS[1].replace("3.0,2.0", "nan,2.0")],
            HEADER,
            {"servo_ids": [2, 1, 3]},
            "column 'tip_x', row 2: value nan is not finite",
        ),
        (
            [ROWS[0], ROWS[1].replace("1.0,-2.0", "x,-2.0")],
            HEADER,
            {"servo_ids": [2, 1, 3]},
            "column 'servo_2_mm', row 2: 'x' is not a number",
        ),
        (ROWS[:2], HEADER, {}, "no pattern label 'tendon1_id<servo>' says which servo drives tendon 1"),
        (ROWS, HEADER, {"n_wires": 6}, "3 servo columns but the design has 6 wires"),
        (ROWS, HEADER, {"servo_ids": [2, 1, 4]}, "missing column 'servo_4_mm'"),
        ([ROWS[1], ROWS[0]], HEADER, {"servo_ids": [2, 1, 3]}, "column 'timestamp', row 2"),
        (ROWS + ["3.0,rep1_tendon0_id1_pull,0,0,0,0,0,188"], HEADER, {}, "tendon 0 is driven by servo 1"),
        ([ROWS[0] + ",7"] + ROWS[1:], HEADER, {}, "row 1: the row has 9 fields, the header 8"),
    ],
)
def test_opencr_errors_name_column_and_row(tmp_path, rows, header, kw, message):
    with pytest.raises(DataError, match=message.replace("(", r"\(").replace(")", r"\)")) as e:
        read_opencr(write_ocr(tmp_path, rows, header), **kw)
    assert "\n" not in str(e.value)


def test_opencr_servo_map_from_labels():
    assert servo_map_from_labels("f", ["rep1_tendon4_id2_pull", "x", "rep2_tendon4_id2_pull"]) == {4: 2}


def test_grouped_recordings_hold_out_whole_groups(tmp_path):
    rows = [f"{i:.1f},rep1_g{i // 5}_dir0,{i % 3},0,0,{i},0,188" for i in range(40)]
    d = read_opencr(write_ocr(tmp_path, rows), servo_ids=[2, 1, 3])
    train, held = d.split(0.25)
    groups = np.asarray(d.groups)
    assert set(groups[held]) == {"rep1_g3_dir0", "rep1_g7_dir0"}  # every 4th group, from the 4th
    assert not set(groups[held]) & set(groups[train])
    both = d.concat(d)
    assert both.reset.sum() == 2 and both.n_samples == 80


def test_home_memory_tells_memory_from_drift():
    """A recording that returns home after excursions in random directions: at home the tip sits 4 mm
    towards the excursion it came from and drifts 0.05 mm per minute in x. ``home_memory`` recovers
    both; without timestamps the drift is per sample; too few home samples is a clear error."""
    from tension_zones.calibration import Dataset, home_memory

    rng = np.random.default_rng(3)
    q, p, stamps = [], [], []
    t = 0.0
    for _ in range(40):
        u = np.r_[rng.normal(size=2), 0.0]
        u /= np.linalg.norm(u)
        for s in np.r_[np.linspace(0.2, 1.0, 10), np.linspace(1.0, 0.2, 10)]:  # out and back
            q.append(np.full(3, -2.0 * s))
            p.append([0.0, 0.0, 100.0] + 50.0 * s * u)
            stamps.append(t)
            t += 1.5  # s
        for _ in range(3):  # home: the memory, the drift, noise
            q.append(np.zeros(3))
            p.append([0.0, 0.0, 100.0] + 4.0 * u + [0.05 * t / 60.0, 0.0, 0.0] + rng.normal(0.0, 0.05, 3))
            stamps.append(t)
            t += 1.5
    q, p = np.array(q), np.array(p)
    data = Dataset(sample=np.arange(len(q)), q=q, f=np.zeros_like(p), p=p, timestamp=np.array(stamps))
    h = home_memory(data)
    assert h["n"] == 40 * 3 and h["time_unit"] == "minute"
    assert abs(h["along_mm"] - 4.0) < 0.2
    assert abs(h["drift_mm"][0] - 0.05) < 0.01 and np.all(np.abs(h["drift_mm"][1:]) < 0.01)
    h = home_memory(dataclasses.replace(data, timestamp=None))
    assert h["time_unit"] == "sample" and abs(h["drift_mm"][0] - 0.05 * 1.5 / 60.0) < 2e-4
    with pytest.raises(ValueError, match="home samples"):
        home_memory(dataclasses.replace(data, q=q + 5.0))


@pytest.mark.parametrize("value", ["99999", "1e308", "-4000"])
def test_a_tracker_glitch_is_dropped_and_listed(good, tmp_path, value):
    """One tracker glitch (an absurd position while the commands move smoothly) is found before any fit,
    against the recording's own median second difference, dropped and listed; nothing else is."""
    lines, _ = good
    data = read_csv(write(tmp_path, edit(lines, 30, "py", value)))
    assert data.n_samples == len(lines) - 2
    (d,) = data.dropped
    assert d["row"] == 30 and d["column"] == "py" and d["reason"].startswith("tracker glitch")
    assert read_csv(write(tmp_path, lines)).dropped == ()


def test_the_shipped_recordings_have_no_glitch():
    """The detector leaves every shipped recording whole: motion reversals and jumps between patterns
    are not glitches."""
    import tension_zones as tz

    train = read_opencr(tz.example_path("ftdcr_v4/train.csv"), n_wires=9)
    sets = [train, read_opencr(tz.example_path("ftdcr_v4/val.csv"), n_wires=9, servo_ids=train.servo_ids)]
    sets += [
        read_opencr(tz.example_path(f"ftdcr_v{v}/{f}.csv"), n_wires=9) for v in (4, 6) for f in ("tendon_pull",)
    ] + [read_opencr(tz.example_path("ftdcr_v6/train.csv"), n_wires=9)]
    sets += [read_csv(tz.example_path(f"synthetic/{n}.csv")) for n in ("nominal_3w", "unknown_a_3w", "unknown_b_4w")]
    assert all(s.dropped == () for s in sets)


def test_a_glitch_leaves_the_calibration_as_it_was(tmp_path):
    """The same recording with one glitch names the same effect, to the same error."""
    import tension_zones as tz
    from tension_zones.calibration import calibrate

    design = tz.Design.from_json(tz.example_path("synthetic/unknown_a_3w.design.json"))
    lines = tz.example_path("synthetic/unknown_a_3w.csv").read_text().splitlines()
    clean = calibrate(read_csv(write(tmp_path, lines)), design).to_json()
    bad = read_csv(write(tmp_path, edit(lines, 200, "px", "99999")))
    got = calibrate(bad, design).to_json()
    assert [e["name"] for e in got["effects"]] == [e["name"] for e in clean["effects"]] == ["backlash"]
    assert got["dropped_rows"] == 1 and abs(got["rmse_after_mm"] - clean["rmse_after_mm"]) < 0.01

"""Measurement sets: validation errors are one line naming column and row; --drop-bad drops and counts."""

import numpy as np
import pytest
from simulator import Truth, write_set

from tension_zones.calibration import DataError, load_csv
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
    ds = load_csv(write_tmp(lines), 3, 20.0)
    assert ds.n_samples == 60 and ds.n_wires == 3 and ds.dropped == ()


def write_tmp(lines, _n=[0]):
    import tempfile
    from pathlib import Path

    _n[0] += 1
    p = Path(tempfile.mkdtemp()) / f"d{_n[0]}.csv"
    p.write_text("\n".join(lines) + "\n")
    return p


@pytest.mark.parametrize("mutate, needle", [
    (lambda L: edit(L, 7, "px", "nan"), "column 'px', row 7"),
    (lambda L: edit(L, 12, "q2", "inf"), "column 'q2', row 12"),
    (lambda L: edit(L, 5, "fz", "abc"), "column 'fz', row 5"),
    (lambda L: edit(L, 9, "sample", "7"), "column 'sample', row 9"),
    (lambda L: edit(L, 3, "q1", "25.0"), "column 'q1', row 3"),
    (lambda L: edit(L, 4, "rx", "4.0"), "column 'rx', row 4"),
    (lambda L: edit(L, 6, "fx", "1e5"), "column 'fx', row 6"),
])
def test_bad_values_name_column_and_row(good, mutate, needle):
    lines, _ = good
    with pytest.raises(DataError, match=needle.replace("(", r"\(")) as e:
        load_csv(write_tmp(mutate(lines)), 3, 20.0)
    assert "\n" not in str(e.value)


def test_missing_column(good):
    lines, _ = good
    header = lines[0].split(",")
    drop = header.index("py")
    cut = [",".join(c for i, c in enumerate(l.split(",")) if i != drop) for l in lines]
    with pytest.raises(DataError, match="missing column 'py'"):
        load_csv(write_tmp(cut), 3, 20.0)


def test_wire_count_disagrees_with_design(good):
    lines, _ = good
    with pytest.raises(DataError, match="the design has 4 wires but .* has 3 wire columns"):
        load_csv(write_tmp(lines), 4, 20.0)


def test_drop_bad_drops_isolated_rows_and_counts_them(good):
    lines, _ = good
    bad = edit(edit(lines, 7, "px", "nan"), 30, "sample", "3")
    ds = load_csv(write_tmp(bad), 3, 20.0, drop_bad=True)
    assert ds.n_samples == 58
    assert [d["row"] for d in ds.dropped] == [7, 30]
    assert {d["column"] for d in ds.dropped} == {"px", "sample"}
    assert 6 not in ds.sample and ds.sample.tolist() == sorted(ds.sample.tolist())


def test_drop_bad_refuses_runs_and_many(good):
    lines, _ = good
    run = edit(edit(edit(lines, 7, "px", "nan"), 8, "py", "nan"), 9, "pz", "nan")
    with pytest.raises(DataError, match="not isolated"):
        load_csv(write_tmp(run), 3, 20.0, drop_bad=True)
    many = lines
    for r in range(2, 60, 6):
        many = edit(many, r, "pz", "nan")
    with pytest.raises(DataError, match="not isolated"):
        load_csv(write_tmp(many), 3, 20.0, drop_bad=True)


def test_cli_errors_are_one_line(good, tmp_path, capsys):
    lines, dj = good
    bad = write(tmp_path, edit(lines, 7, "px", "nan"))
    assert main(["calibrate", str(bad), "--design", str(dj), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "column 'px', row 7" in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()
    assert main(["calibrate", str(tmp_path / "nope.csv"), "--design", str(dj), "--out",
                 str(tmp_path / "o")]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert main(["calibrate", str(bad), "--design", str(dj), "--out", str(tmp_path / "o"),
                 "--holdout", "1.5"]) == 2
    assert capsys.readouterr().err.count("\n") == 1


def test_samples_out_of_order(good):
    lines, _ = good
    swapped = list(lines)
    swapped[10], swapped[11] = swapped[11], swapped[10]
    with pytest.raises(DataError, match="column 'sample', row 11: samples must be in acquisition order"):
        load_csv(write_tmp(swapped), 3, 20.0)


def test_split_in_acquisition_order(good):
    lines, _ = good
    ds = load_csv(write_tmp(lines), 3, 20.0)
    train, held = ds.split(0.25)
    assert train.sum() == 45 and np.all(train[:45]) and np.all(held[45:])
    with pytest.raises(DataError, match="holdout"):
        ds.split(0.0)

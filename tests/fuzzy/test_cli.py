"""``rover-ctl fuzzy eval|show`` end to end through the CLI entry point."""

import csv
import io

import pytest

from rover_ctl.cli import main

HEADER = "target_distance,target_direction,obstacle_left,obstacle_front,obstacle_right,obstacle_back,label"
ROWS = ["8.0912,58.865,9.4708,11.6025,25.0,5.5469,a", "2.3776,260.8843,3.323,25.0,20.0,16.9835,b"]


def run(argv, capsys, stdin=None, monkeypatch=None):
    if stdin is not None:
        monkeypatch.setattr("sys.stdin", io.StringIO(stdin))
    code = main(argv)
    captured = capsys.readouterr()
    return code, captured.out, captured.err


def test_eval_file_to_file_keeps_columns_and_appends_outputs(tmp_path, capsys):
    source, target = tmp_path / "in.csv", tmp_path / "out.csv"
    source.write_text("\n".join([HEADER, *ROWS]) + "\n")
    code, out, err = run(["fuzzy", "eval", "--rulebase", "paper", "--input", str(source), "--output", str(target)], capsys)
    assert (code, out, err) == (0, "", "")
    rows = list(csv.DictReader(target.open()))
    assert [r["label"] for r in rows] == ["a", "b"]
    assert float(rows[0]["left_motor"]) == pytest.approx(98.5982819, abs=0.05)
    assert float(rows[1]["right_motor"]) == pytest.approx(-1.59983265, abs=0.05)


def test_eval_reads_a_csv_with_a_byte_order_mark(tmp_path, capsys):
    """Spreadsheets save CSV with a BOM: it was read as part of the first column's name."""
    source = tmp_path / "in.csv"
    source.write_bytes(b"\xef\xbb\xbf" + "\n".join([HEADER, ROWS[0]]).encode())
    code, out, err = run(["fuzzy", "eval", "--rulebase", "paper", "--input", str(source)], capsys)
    assert (code, err) == (0, "")
    assert out.splitlines()[0] == HEADER + ",left_motor,right_motor"


def test_eval_stdin_stdout_with_explain(capsys, monkeypatch):
    code, out, _ = run(["fuzzy", "eval", "--rulebase", "paper", "--explain"], capsys, "\n".join([HEADER, ROWS[0]]), monkeypatch)
    assert code == 0
    row = next(csv.DictReader(io.StringIO(out)))
    assert row["rules"].startswith("#449=0.555 #448=0.445")


@pytest.mark.parametrize(
    "text, message",
    [
        ("target_distance,label\n1,a\n", "<stdin>: missing input column(s) target_direction"),
        (HEADER + "\n1,2,3,x,5,6,a\n", "<stdin> line 2 column obstacle_front: not a number: 'x'"),
        (HEADER + "\n1,2,3\n", "<stdin> line 2: 3 fields, the header has 7"),
        (HEADER + "\n1,2,3,4,5,6," + "a" * 200_000 + "\n", "<stdin> line 2: not CSV: field larger than field limit"),
    ],
)
def test_eval_bad_input_is_one_line_exit_2(capsys, monkeypatch, text, message):
    code, out, err = run(["fuzzy", "eval", "--rulebase", "paper"], capsys, text, monkeypatch)
    assert code == 2 and out == ""
    assert err == f"rover-ctl: error: {message}" + err.split(message, 1)[1]
    assert err.count("\n") == 1


def test_unknown_rulebase(capsys):
    code, _, err = run(["fuzzy", "show", "nonesuch"], capsys)
    assert code == 2 and "nonesuch: no such rule base file or shipped name" in err


def test_show_prints_variables_rules_and_plots(tmp_path, capsys):
    png = tmp_path / "sets.png"
    code, out, _ = run(["fuzzy", "show", "paper", "--plot", str(png)], capsys)
    assert code == 0
    assert "input target_direction [deg] range 0..360, circular period 360" in out
    assert "forward_fast     133.34 200 200 266.67" in out
    assert "972 rules" in out and "warning: paper.toml: 1 input combination(s) have no rule for left_motor" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_show_plot_says_which_file_it_wrote(tmp_path, capsys):
    """matplotlib adds .png to a name without a suffix; the message named the path as given."""
    code, out, _ = run(["fuzzy", "show", "default", "--plot", str(tmp_path / "sets")], capsys)
    assert code == 0 and f"drawn to {tmp_path / 'sets.png'}" in out and (tmp_path / "sets.png").is_file()
    code, _, err = run(["fuzzy", "show", "default", "--plot", str(tmp_path)], capsys)
    assert code == 2 and f"--plot {tmp_path}: is a folder" in err


BAD_DEFAULT = """
[inputs.x]
range = [0, 10]
sets = { lo = [0, 0, 0, 10], hi = [0, 10, inf, inf] }
[outputs.y]
range = [0, 10]
default = inf
sets = { a = [0, 2, 4], b = [6, 8, 10] }
[rules]
list = ["if x is lo then y is a", "if x is hi then y is b"]
"""


@pytest.mark.parametrize("command", [["fuzzy", "show"], ["fuzzy", "eval", "--rulebase"]])
def test_a_non_finite_default_is_refused_in_one_line(tmp_path, capsys, monkeypatch, command):
    path = tmp_path / "bad.toml"
    path.write_text(BAD_DEFAULT)
    code, out, err = run([*command, str(path)], capsys, "x\n1\n", monkeypatch)
    assert (code, out) == (2, "")
    assert err == "rover-ctl: error: bad.toml [outputs.y] default: expected a finite number, got inf\n"

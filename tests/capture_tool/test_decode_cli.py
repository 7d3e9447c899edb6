"""``effortface decode`` through the real command line, and the heart_rate.csv row format."""

from __future__ import annotations

import argparse
import io
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.capture_tool.captures import read_timed_capture
from effortface.capture_tool.commands import decode as cmd
from effortface.core.errors import SessionFormatError
from effortface.core.session.hr_csv import HR_CSV_COLUMNS, format_hr_row, read_hr_csv
from effortface.capture_tool.protocols import HrSample
from effortface.capture_tool.serlog import SerlogWriter, read_serlog
from effortface.cli import main

HXM = "serial/zephyr-bt/120-second-bt-stream-hxm.dat"
ANT_EXT = "serial/derived/njcant_hrm1_ant_broadcast_ext.bin"


def test_decode_hxm_in_a_subprocess(shared_data, tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "effortface", "decode", "--protocol", "hxm", str(shared_data / HXM)],
        capture_output=True, text=True, timeout=60, check=False,
    )
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert lines[0] == ",".join(HR_CSV_COLUMNS) and len(lines) == 1 + 142
    assert lines[1] == "0.0000,67,,101,hxm,1"
    assert lines[2] == "0.7000,67,884,102,hxm,1"  # 0.7 s after the first read, as recorded
    assert proc.stderr.count("\n") == 1 and "frames_ok=142" in proc.stderr
    (tmp_path / "hr.csv").write_text(proc.stdout)
    rows = read_hr_csv(tmp_path / "hr.csv")
    assert sum(len(r.rr_ms) for r in rows) == 207 and rows[-1].beat_count == 52


def test_serlog_decodes_like_the_raw_capture(shared_data, tmp_path, capsys):
    """The same reads stored in a .serlog (as capture writes them) give the same CSV."""
    log = tmp_path / "hxm.serlog"
    with SerlogWriter(log, {"device": "hxm", "protocol": "hxm"}) as writer:
        for t_s, data in read_timed_capture(shared_data / HXM):
            writer.write(t_s, data)
    assert main(["decode", "--protocol", "hxm", str(log)]) == 0
    from_log = capsys.readouterr().out
    assert main(["decode", "--protocol", "hxm", str(shared_data / HXM)]) == 0
    assert from_log == capsys.readouterr().out


def test_a_serlog_names_its_own_protocol(shared_data, tmp_path, capsys):
    """--protocol may be left out for a .serlog (its header names it); given, it wins with a note."""
    log = tmp_path / "hxm.serlog"
    with SerlogWriter(log, {"device": "hxm", "protocol": "hxm"}) as writer:
        for t_s, data in read_timed_capture(shared_data / HXM):
            writer.write(t_s, data)
    assert main(["decode", str(log)]) == 0
    implicit = capsys.readouterr()
    assert main(["decode", "--protocol", "hxm", str(log)]) == 0
    explicit = capsys.readouterr()
    assert implicit.out == explicit.out and len(implicit.out.splitlines()) == 1 + 142
    assert main(["decode", "--protocol", "lines", str(log)]) == 0
    err = capsys.readouterr().err
    assert "recorded as 'hxm'; decoding as --protocol lines" in err


def test_a_raw_capture_without_protocol_is_one_clear_line(shared_data, capsys):
    assert main(["decode", str(shared_data / HXM)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("effortface decode: error: --protocol: expected one of ant, ")
    assert "120-second-bt-stream-hxm.dat" in err[0] and "found none" in err[0]


def test_decode_ant_extended_through_main(shared_data, capsys):
    assert main(["decode", "--protocol", "ant", str(shared_data / ANT_EXT)]) == 0
    out, err = capsys.readouterr()
    rows = out.splitlines()[1:]
    assert len(rows) == 686 and all(r.split(",")[4] == "ant:3425" for r in rows)
    assert rows[2].split(",")[2] == "920.8984375"
    assert "beat_time_wraps=11" in err


def test_device_type_filter(shared_data, capsys):
    assert main(["decode", "--protocol", "ant", "--device-type", "11", str(shared_data / ANT_EXT)]) == 0
    assert capsys.readouterr().out.splitlines() == [",".join(HR_CSV_COLUMNS)]


def test_libant_pcap_decodes_to_no_rows(shared_data, capsys):
    path = shared_data / "serial/libant/demo-capture-1.pcap"
    assert main(["decode", "--protocol", "ant", str(path)]) == 0
    out, err = capsys.readouterr()
    assert out.splitlines() == [",".join(HR_CSV_COLUMNS)] and "frames_ok=1888" in err


@pytest.mark.parametrize("argv, message", [
    (["--protocol", "polar", "{hxm}"], "--protocol: expected one of ant, ble_hrm, hrmi, hxm, lines, found 'polar'"),
    (["--protocol", "hxm", "{missing}"], "missing.dat: expected a readable capture file"),
    (["--protocol", "hxm", "--device-type", "120", "{hxm}"], "--device-type: expected only with"),
    (["--protocol", "ant", "--device-type", "300", "{hxm}"], "--device-type: expected an ANT device"),
    (["--protocol", "hxm", "{csv}"], "expected a .serlog, .pcap or raw"),
])
def test_user_errors_are_one_line_and_exit_2(shared_data, tmp_path, capsys, argv, message):
    paths = {"{hxm}": str(shared_data / HXM), "{missing}": str(tmp_path / "missing.dat"),
             "{csv}": str(tmp_path / "hr.csv")}
    (tmp_path / "hr.csv").write_text("t_s\n")
    assert main(["decode", *[paths.get(a, a) for a in argv]]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and message in err
    assert err.startswith("effortface decode: error: ")


# -- heart_rate.csv rows -----------------------------------------------------------------------
@pytest.mark.parametrize("sample, row", [
    (HrSample(1.23456, 72.0, (833.0, 812.5), 17, "ant:3425", True), "1.2346,72,833 812.5,17,ant:3425,1"),
    (HrSample(2.0, None, (), None, "hxm", False), "2.0000,,,,hxm,0"),
    (HrSample(0.5, 64.5, (), 3, "lines", True), "0.5000,64.5,,3,lines,1"),
])
def test_format_hr_row(sample, row):
    assert format_hr_row(sample) == row


def test_hr_csv_round_trip(tmp_path):
    samples = [HrSample(0.25, 70.0, (850.0,), 1, "hxm", True), HrSample(1.5, None, (), 2, "hxm", False)]
    path = tmp_path / "heart_rate.csv"
    path.write_text(",".join(HR_CSV_COLUMNS) + "\n" + "".join(format_hr_row(s) + "\n" for s in samples))
    assert read_hr_csv(path) == samples


@pytest.mark.parametrize("content, message", [
    ("t,hr\n1,2\n", r"expected header 't_s,hr_bpm,rr_ms,beat_count,device,valid', found 't,hr'"),
    ("t_s,hr_bpm,rr_ms,beat_count,device,valid\nabc,70,,1,hxm,1\n", r"line 2: expected a heart-rate row"),
])
def test_read_hr_csv_refuses_bad_files(tmp_path, content, message):
    (tmp_path / "hr.csv").write_text(content)
    with pytest.raises(SessionFormatError, match=message):
        read_hr_csv(tmp_path / "hr.csv")


def test_run_writes_to_a_given_stream(shared_data):
    buf = io.StringIO()
    args = argparse.Namespace(protocol="hxm", device_type=None, file=str(shared_data / HXM))
    assert cmd.run(args, out=buf) == 0
    assert len(buf.getvalue().splitlines()) == 143


ROOT_SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"


@pytest.mark.parametrize("session", sorted(
    p.name for p in ROOT_SAMPLES.glob("P*_*") if (p / "session.json").exists()))
def test_decode_of_a_session_serlog_is_its_heart_rate_csv(session, capsys):
    """`effortface decode` keeps a .serlog's session times: it reproduces heart_rate.csv exactly."""
    folder = ROOT_SAMPLES / session
    (serlog,) = sorted((folder / "serial").glob("*.serlog"))
    protocol = read_serlog(serlog).header["protocol"]
    assert main(["decode", "--protocol", protocol, str(serlog)]) == 0
    assert capsys.readouterr().out == (folder / "heart_rate.csv").read_text()

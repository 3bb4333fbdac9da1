"""The command line's errors speak its own language: a value in the wrong unit is named by its
flag, the value, the flag's unit and the likely slip (``--radius is in um; ... did you give
metres? use --radius 1.53``), never by the Python API's parameter names or options
(``check_units=False``, ``min_exposure``, ``dead_time``, ``friction_error=...``); and no
range with its ends the wrong way round (``[0, -0.00133)``) is printed."""

import re

import pytest

from blurtrap.cli import main

#: what the command line never says: Python-only options and SI parameter names
PYTHON_WORDS = re.compile(r"check_units|design takes|\bpositions have\b|\b[a-z]+_[a-z_]+ ?=|"
                          r"\b(?:min_exposure|max_fps|dead_time|tracking_std|friction_error|"
                          r"n_frames|total_time|laser_power|frame_interval|f_range|"
                          r"excluded_ranges)\b")
#: a range printed with its upper end below zero or below its lower end
BAD_RANGE = re.compile(r"\[0, -|, -\d[^\]\)]*[\)\]]")


def _error_line(err: str, command: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith(f"blurtrap {command}: error: "), err
    line = lines[0]
    assert not PYTHON_WORDS.search(line), line
    assert not BAD_RANGE.search(line), line
    return line


def _with_defaults(argv, defaults):
    """`argv` plus each ``(flag, value)`` of `defaults` whose flag (or an alternative of it,
    ``"--gamma|--radius"``) it does not give."""
    out = list(argv)
    for flags, value in defaults:
        if not any(f in argv for f in flags.split("|")):
            out += [flags.split("|")[-1], *value.split()]
    return out


SIMULATE = (("--k", "0.05"), ("--exposure-ms", "0.5"), ("--frames", "256"), ("--gamma|--radius", "1.5"))


@pytest.mark.parametrize("argv, pattern", [
    (["--radius", "1.53e-6"], r"--radius is in um; 1\.53e-06 um is below .*: did you give metres\? "
                              r"use --radius 1\.53$"),
    (["--radius", "1530"], r"--radius is in um; 1530 um is above .*: did you give nm\? use --radius 1\.53$"),
    (["--gamma", "2.68e-8"], r"--gamma is in pN s/um; 2\.68e-08 pN s/um is below .*: did you give N s/m\? "
                             r"use --gamma 0\.0268$"),
    (["--radius", "1", "--viscosity", "950"], r"--viscosity is in Pa s; .*950 Pa s.*did you give mPa s\? "
                                              r"use --viscosity 0\.95$"),
    (["--radius", "1", "--k", "5000"], r"--k is in pN/nm; 5000 pN/nm is above .*: did you give pN/um\? "
                                       r"use --k 5$"),
    (["--radius", "1", "--fps", "1.5"], r"--fps is in Hz; 1\.5 Hz .*: did you give kHz\? use --fps 1500$"),
    (["--radius", "1", "--temperature", "22"], r"--temperature is in K; 22 K is below .*: did you give "
                                               r"Celsius\? use --temperature 295\.15$"),
    (["--radius", "1", "--tracking-nm", "2e4"], r"--tracking-nm is in nm; 20000 nm is above "),
    (["--radius", "1", "--power-mw", "5e4"], r"--power-mw is in mW; 50000 mW is above .*: did you give uW\? "
                                             r"use --power-mw 50$"),
    (["--radius", "1", "--power-mw", "-5"], r"--power-mw must be >= 0 mW; got -5"),
])
def test_simulate_unit_slip_names_the_flag(tmp_path, capsys, argv, pattern):
    capsys.readouterr()
    assert main(["simulate", *_with_defaults(argv, SIMULATE), "--out", str(tmp_path / "o")]) == 1
    line = _error_line(capsys.readouterr().err, "simulate")
    assert re.search(pattern, line), line
    assert not (tmp_path / "o").exists()  # refused before anything was simulated or written


def test_simulate_blurred_away_positions_name_the_flags(tmp_path, capsys):
    """A stiff trap filmed with long exposures: the blur leaves positions that scatter less
    than the loaders accept (0.02 nm); the message says so in the command's flags."""
    capsys.readouterr()
    argv = _with_defaults(["--k", "50", "--radius", "1.5"], SIMULATE)
    assert main(["simulate", *argv, "--out", str(tmp_path / "o")]) == 1
    line = _error_line(capsys.readouterr().err, "simulate")
    assert re.search(r"below 0\.02 nm", line), line
    for flag in ("--k 50", "--exposure-ms 0.5", "--radius"):
        assert flag in line, line


DESIGN = (("--k", "0.05"), ("--max-fps", "1500"), ("--total-s|--frames", "4096"), ("--series", "1"),
          ("--gamma|--radius-um", "1.5"))


@pytest.mark.parametrize("argv, pattern", [
    (["--k", "5000"], r"--k is in pN/nm; 5000 pN/nm is above .*: did you give pN/um\? use --k 5$"),
    (["--k", "0.05", "5e-8"], r"--k is in pN/nm; 5e-08 pN/nm is below .*: did you give N/m\? use --k 5e-05$"),
    (["--gamma", "9.5e-9"], r"--gamma is in pN s/um; 9\.5e-09 pN s/um is below .*: did you give N s/m\? "
                            r"use --gamma 0\.0095$"),
    (["--radius-um", "1.5e-6"], r"--radius-um is in um; 1\.5e-06 um is below .*: did you give metres\? "
                                r"use --radius-um 1\.5$"),
    (["--radius-um", "1500"], r"--radius-um is in um; 1500 um is above .*: did you give nm\? "
                              r"use --radius-um 1\.5$"),
    (["--radius-um", "1", "--viscosity", "950"], r"--viscosity is in Pa s; .*did you give mPa s\? "
                                                 r"use --viscosity 0\.95$"),
    (["--temperature", "22"], r"--temperature is in K; 22 K is below .*Celsius\? use --temperature 295\.15$"),
    (["--temperature", "295000"], r"--temperature is in K; 295000 K is above .*mK\? use --temperature 295$"),
    (["--min-exposure-ms", "500"], r"--min-exposure-ms is in ms; 500 ms is .*: did you give us\? "
                                   r"use --min-exposure-ms 0\.5$"),
    (["--tracking-nm", "2e4"], r"--tracking-nm is in nm; 20000 nm is above "),
    (["--tracking-nm", "-1"], r"--tracking-nm must be >= 0 nm; got -1"),
    (["--max-fps", "-5"], r"--max-fps must be > 0 Hz; got -5"),
    (["--min-exposure-ms", "-1"], r"--min-exposure-ms must be > 0 ms; got -1"),
    (["--friction-error", "-3"], r"--friction-error is a relative error in %, >= 0; got -3"),
    (["--min-exposure-ms", "2"], r"--min-exposure-ms 2 is longer than the frame interval at --max-fps 1500 "
                                 r"\(0\.667 ms\): an exposure cannot be longer than the frame interval; "
                                 r"lower --min-exposure-ms or --max-fps$"),
    (["--min-exposure-ms", "0.5", "--max-fps", "2000"], r"--min-exposure-ms 0\.5 is as long as the frame "
                                                        r"interval at --max-fps 2000 \(0\.5 ms\)"),
    (["--dead-time-ms", "1"], r"--dead-time-ms 1 leaves no time for an exposure: .*below 0\.666 ms"),
    (["--dead-time-ms", "20"], r"--dead-time-ms 20 leaves no time .*: did you give us\? use --dead-time-ms 0\.02$"),
    (["--dead-time-ms", "-1"], r"--dead-time-ms must be >= 0 ms; got -1"),
    (["--powers", "0"], r"--powers takes at least 2 distinct powers > 0, as multiples of the power --k is at "
                        r"\(e\.g\. --powers 0\.5,1,2\); got --powers 0$"),
    (["--powers", "0.5,1,1"], r"--powers takes at least 2 distinct .*; got --powers 0\.5,1,1$"),
    (["--powers", "0.5,-1"], r"--powers takes at least 2 distinct .*; got --powers 0\.5,-1$"),
    (["--series", "1", "0"], r"--series takes numbers of exposures >= 1 to try \(e\.g\. --series 1 2 3\); "
                             r"got --series 1 0$"),
    (["--total-s", "0.01"], r"--total-s 0\.01 is 15 frames at --max-fps 1500, too few to split into 4 "
                            r"recordings \(the largest candidate\) of at least 64 frames each: use --total-s "
                            r"0\.171 or more$"),
    (["--total-s", "0.3", "--series", "10"], r"--total-s 0\.3 is 450 frames .* into 10 recordings .*: use "
                                             r"--total-s 0\.427 or more, or fewer exposures in --series$"),
    (["--total-s", "0", "--series", "10"], r"--total-s must be > 0 s; got 0$"),
])
def test_design_bad_values_name_the_flag(capsys, argv, pattern):
    capsys.readouterr()
    assert main(["design", *_with_defaults(argv, DESIGN)]) == 1
    line = _error_line(capsys.readouterr().err, "design")
    assert re.search(pattern, line), line


def test_design_slow_frame_rate_warns_and_fails_in_cli_words(capsys):
    """--max-fps 1.5 (kHz given as Hz): a warning naming the flag, and the design that cannot
    identify k and gamma says which flag gives the friction; no Python option is named."""
    capsys.readouterr()
    assert main(["design", "--k", "0.05", "--radius-um", "1.5", "--max-fps", "1.5", "--frames", "4096",
                 "--series", "1"]) == 1
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 2, err
    assert re.search(r"^blurtrap design: warning: --max-fps is in Hz; 1\.5 Hz .*: if the camera runs at "
                     r"1\.5 kHz, use --max-fps 1500$", lines[0]), err
    assert not PYTHON_WORDS.search(lines[0]), lines[0]
    line = _error_line(lines[1], "design")
    assert "--friction-error" in line, line


@pytest.mark.parametrize("argv, pattern", [
    (["--f-range", "500", "100"], r"--f-range FMIN FMAX needs 0 <= FMIN < FMAX \[Hz\]; got --f-range 500 100$"),
    (["--f-range", "-5", "100"], r"--f-range FMIN FMAX needs 0 <= FMIN < FMAX \[Hz\]; got --f-range -5 100$"),
    (["--exclude", "60", "50"], r"--exclude F_LOW F_HIGH needs 0 <= F_LOW < F_HIGH \[Hz\]; got --exclude 60 50$"),
])
def test_calibrate_reversed_bands_name_the_flag(tmp_path, capsys, monkeypatch, argv, pattern):
    import blurtrap.inference as inf

    def boom(*a, **kw):
        raise AssertionError("calibrate ran before the bands were checked")

    manifest = tmp_path / "m.json"
    manifest.write_text("{}")
    monkeypatch.setattr(inf, "calibrate", boom)
    capsys.readouterr()
    assert main(["calibrate", str(manifest), "--method", "psd", *argv]) == 1
    line = _error_line(capsys.readouterr().err, "calibrate")
    assert re.search(pattern, line), line


@pytest.fixture(scope="module")
def manifest(tmp_path_factory):
    """A 4096-frame trace at 1500 fps (f_c ~ 300 Hz) from an AR(1) recursion in numpy."""
    import math

    import numpy as np
    from scipy.signal import lfilter

    import blurtrap as bt

    rng = np.random.default_rng(3)
    k, gamma, dt = 5e-5, 2.68e-8, 1 / 1500
    rho, sig = math.exp(-dt * k / gamma), math.sqrt(1.380649e-23 * 295.0 / k)
    x = lfilter([1.0], [1.0, -rho], rng.standard_normal(4096) * sig * math.sqrt(1 - rho**2))
    path = tmp_path_factory.mktemp("band") / "m.json"
    bt.save_manifest(bt.Recording(x, frame_interval=dt, exposure=1e-5), path)
    return str(path)


@pytest.mark.parametrize("argv, pattern", [
    (["--f-range", "0.1", "0.5"], r"--f-range 0\.1 0\.5 keeps only 1 periodogram ordinate\(s\) .*; --f-range is "
                                  r"in Hz: did you mean --f-range 100 500\?$"),
    (["--f-range", "10", "5000"], r"--f-range 10 5000: FMAX = 5000 Hz is above the Nyquist frequency fs/2 = 750 Hz "
                                  r".*expected FMAX <= fs/2 \(--f-range is in Hz, not kHz\)$"),
    (["--f-range", "1000", "2000"], r"--f-range 1000 2000 starts above the Nyquist frequency 750 Hz"),
])
def test_calibrate_band_messages_name_the_flag(manifest, capsys, argv, pattern):
    """The API's band refusals (``f_range = (0.1, 0.5) Hz ... did you mean (100, 500) Hz?``)
    in the command line's flags."""
    capsys.readouterr()
    assert main(["calibrate", manifest, "--method", "psd", *argv]) == 1
    line = _error_line(capsys.readouterr().err, "calibrate")
    assert re.search(pattern, line), line


def test_calibrate_failed_fit_names_the_band_flags(manifest, capsys, monkeypatch):
    """A fit that fails in a band the user chose names it by --f-range and --exclude."""
    from blurtrap.inference import FitError
    from blurtrap.inference import _calibrate as cal_mod

    def refuse(*a, **k):
        raise FitError("psd fit: the Fisher information is singular")

    monkeypatch.setattr(cal_mod, "_calibrate", refuse)
    capsys.readouterr()
    argv = ["--f-range", "100", "200", "--exclude", "150", "160", "--exclude", "170", "170.5"]
    assert main(["calibrate", manifest, "--method", "psd", *argv]) == 1
    line = _error_line(capsys.readouterr().err, "calibrate")
    assert re.search(r"confined to --f-range 100 200 and --exclude 150 160 --exclude 170 170\.5: \d+ of the "
                     r"2048 periodogram ordinates\..* widen --f-range", line), line

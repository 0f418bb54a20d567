"""The run progress bar (scenes.common.run_frames): no estimate from the first step, the
compile label only while numba compiles, time left to an expected stop (#46 item 4)."""

import re
import time

import numba
import numpy as np

from clusterdyn.scenes.common import run_frames


class FakeDyn:
    """``run(k)``: the first step takes ``first`` s (a set-up or a compile), later ones ``each`` s;
    ``kernel`` (a numba function) is called at every run."""

    def __init__(self, first=0.0, each=0.0, kernel=None):
        self.nsteps, self.first, self.each, self.kernel = 0, first, each, kernel

    def run(self, k):
        if self.kernel is not None:
            self.kernel(np.ones(3))
        time.sleep((self.first if self.nsteps == 0 else 0.0) + self.each * (k - (self.nsteps == 0)))
        self.nsteps += k


def _lines(err):
    return [s for s in re.split(r"[\r\n]", err) if "step" in s]


def _left_seconds(line):
    m = re.search(r"<([0-9:]+|\?)", line)
    if m is None or m.group(1) == "?":
        return None
    sec = 0
    for part in m.group(1).split(":"):
        sec = 60 * sec + int(part)
    return sec


def test_the_first_slow_step_gives_no_estimate_and_no_false_compile_label(capsys):
    dyn = FakeDyn(first=0.6, each=1e-4)
    run_frames(dyn, 4000, 4, lambda d: None, desc="fake")
    lines = _lines(capsys.readouterr().err)
    assert lines
    # with the slow first step counted, 4000 steps would be estimated at 40 min
    lefts = [_left_seconds(s) for s in lines if re.search(r"\| *[1-9]\d*/4000", s)]
    assert lefts and all(x is None or x < 60 for x in lefts), lines
    assert lefts[0] is None, lines                     # "?" until the steps after the first move
    assert not any("compiling" in s for s in lines), lines   # nothing compiled


def test_the_compile_label_appears_only_while_numba_compiles(capsys):
    @numba.njit(cache=False)
    def kernel(x):
        return x.sum() * 2.0

    run_frames(FakeDyn(kernel=kernel), 40, 4, lambda d: None, desc="fake")
    assert any("compiling kernels" in s for s in _lines(capsys.readouterr().err))
    run_frames(FakeDyn(kernel=kernel), 40, 4, lambda d: None, desc="fake")   # already compiled
    assert not any("compiling" in s for s in _lines(capsys.readouterr().err))


def test_time_left_counts_to_the_expected_stop(capsys):
    class Record:
        def stop(self, d):
            return d.nsteps >= 300

        def expected_steps(self, d):
            return 300

    run_frames(FakeDyn(each=1e-4), 10000, 100, lambda d: None, desc="fake", stop=Record().stop)
    lines = _lines(capsys.readouterr().err)
    assert any(re.search(r"\| *[1-9]\d*/300 ", s) for s in lines), lines[-3:]
    late = [s for s in lines if re.search(r"\| *[1-9]\d\d+/", s)]   # from the first frame on
    assert late and not any("/10000 " in s for s in late), late


def test_taylor_expects_its_stop_from_the_rods_deceleration():
    """The Taylor rod's bar counts to the step the centre of mass comes to rest (plus the stop window),
    not to t_max."""
    from types import SimpleNamespace
    from clusterdyn import units
    from clusterdyn.scenes.taylor import STOP_WINDOW, TaylorRecord
    rec = TaylorRecord.__new__(TaylorRecord)
    dt = 1e-3 * units.us
    rec.t = [0.0, 1.0 * units.us, 2.0 * units.us]
    rec.vz = [-300.0 * units.m_s, -200.0 * units.m_s, -100.0 * units.m_s]     # at rest at 3 us
    want = rec.expected_steps(SimpleNamespace(dt=dt))
    assert abs(want - (3.0 * units.us + STOP_WINDOW) / dt) <= 1
    rec.vz = [-300.0 * units.m_s, -300.0 * units.m_s, -300.0 * units.m_s]     # not decelerating: no estimate
    assert rec.expected_steps(SimpleNamespace(dt=dt)) is None

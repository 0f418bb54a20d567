"""clusterdyn.parallel: the OpenMP waiting settings the CLI sets (import alone sets nothing), and the
user's that it keeps.

libgomp reads them once when it loads, so each case runs in a fresh interpreter.
"""

import json
import os
import subprocess
import sys

import pytest

PROBE = ("import os, json, clusterdyn; {call}"
         "print(json.dumps({{k: os.environ.get(k) for k in ('OMP_WAIT_POLICY', 'GOMP_SPINCOUNT')}}))")
CONFIGURE = "from clusterdyn.parallel import configure_openmp; configure_openmp(); "


def _env_after_import(call=CONFIGURE, **set_vars):
    env = {k: v for k, v in os.environ.items() if k not in ("OMP_WAIT_POLICY", "GOMP_SPINCOUNT")}
    env.update(set_vars)
    out = subprocess.run([sys.executable, "-c", PROBE.format(call=call)], env=env, capture_output=True,
                         text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_short_spin_then_sleep_by_default():
    from clusterdyn.parallel import SPIN_COUNT
    assert _env_after_import() == {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": str(SPIN_COUNT)}


def test_import_alone_changes_no_environment_variable():
    assert _env_after_import(call="") == {"OMP_WAIT_POLICY": None, "GOMP_SPINCOUNT": None}


def test_the_command_makes_the_settings():
    from clusterdyn.parallel import SPIN_COUNT
    call = "import clusterdyn.cli as c; c.main(['materials']); "
    assert _env_after_import(call=call) == {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": str(SPIN_COUNT)}


@pytest.mark.parametrize("given, expected", [
    ({"OMP_WAIT_POLICY": "ACTIVE"}, {"OMP_WAIT_POLICY": "ACTIVE", "GOMP_SPINCOUNT": None}),
    ({"OMP_WAIT_POLICY": "PASSIVE"}, {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": None}),
    ({"GOMP_SPINCOUNT": "0"}, {"OMP_WAIT_POLICY": "PASSIVE", "GOMP_SPINCOUNT": "0"}),
])
def test_the_users_choice_is_kept(given, expected):
    assert _env_after_import(**given) == expected


def test_use_threads_tells_numba_only_when_its_count_changes(monkeypatch):
    """``use_threads`` calls ``numba.set_num_threads`` when its own count changes (per Python thread),
    and again after ``set_max_threads`` or ``forget_threads``; numba's count is clusterdyn's after
    each call."""
    import threading

    import numba

    from clusterdyn import parallel as P
    calls = []
    real = numba.set_num_threads
    monkeypatch.setattr(numba, "set_num_threads", lambda k: (calls.append(k), real(k)))
    big = 2 * P.MIN_PARTICLES_PER_THREAD
    try:
        P.forget_threads()
        P.use_threads(10)
        P.use_threads(20)                     # the same count: numba not told again
        assert calls == [1] and numba.get_num_threads() == 1
        k2 = P.use_threads(big)
        assert calls == [1, k2] and numba.get_num_threads() == k2 == min(2, numba.config.NUMBA_NUM_THREADS)
        P.set_max_threads(1)                  # a new limit applies at once
        assert P.use_threads(big) == 1 and calls[-1] == 1 and numba.get_num_threads() == 1
        real(numba.config.NUMBA_NUM_THREADS)  # set behind clusterdyn's back, then forgotten
        P.forget_threads()
        P.use_threads(big)
        assert numba.get_num_threads() == 1
        seen = []                             # another Python thread has its own numba count
        t = threading.Thread(target=lambda: seen.append((P.use_threads(big), numba.get_num_threads())))
        t.start()
        t.join()
        assert seen == [(1, 1)]
    finally:
        P.set_max_threads(None)

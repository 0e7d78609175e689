"""Long calls keep the contract of docs/api.md, "Long calls": progress at least every ~0.5 s,
a callback returning False stops the call within a second (`translucent.Cancelled`), Ctrl-C
stops it within a second (KeyboardInterrupt), a request over a stated limit is refused up
front naming the limit; and objects shared between Python threads evaluate side by side.

Each call here would run for minutes: it is stopped after about a second."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import translucent
from helpers import plane, sphere

# The contract's figures.
MAX_GAP = 0.5
STOP_WITHIN = 1.0
# How long a call runs before it is stopped (long enough to see several progress calls).
RUN_FOR = 1.2


@pytest.fixture(scope="module")
def marble():
    m = translucent.Material.preset("marble", mm_per_unit=10.0)
    # The walk tables (built once per material, then read from the cache folder): prepared
    # here so that the calls below spend their time in the loops under test.
    translucent.prepare_profile(m)
    return m


@pytest.fixture(scope="module")
def ball():
    p, t = sphere(12, 1.0)
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.2, -1.0), 2.0)
    return s


@pytest.fixture(scope="module")
def lit_by_world():
    p, t = sphere(12, 1.0)
    s = translucent.Scene(p, t)
    s.set_world(color=(0.5, 0.6, 0.7))
    return s


# A medium whose walk tables no other test builds (g, Roughness and IOR off every other
# test's grid): `Prt(...)` builds them inside its own progress.
UNBUILT = dict(sigma_a=(0.5, 1.0, 2.0), sigma_s=(50.0, 60.0, 70.0), g=0.47, eta=2.93)


@pytest.fixture
def unbuilt_tables(tmp_path):
    """The cache folder empty for the call (nothing of it is written: the build is stopped)."""
    before = translucent.table_cache()
    translucent.set_table_cache(str(tmp_path))
    yield translucent.Material(**UNBUILT).with_layers(roughness=0.93)
    translucent.set_table_cache(before)


@pytest.fixture(scope="module")
def big_ball():
    """44,702 vertices: a Hierarchy with fine thresholds links for ~20 s on 2 cores."""
    p, t = sphere(150, 1.0)
    s = translucent.Scene(p, t)
    s.add_sun((0.3, 0.2, -1.0), 2.0)
    return s


def long_calls(ball, lit_by_world, marble, unbuilt=None, big=None):
    """name -> call(progress): each would run for minutes."""
    return {
        "hierarchy": lambda progress: translucent.Hierarchy(big, marble, eps=(1e-6, 1e-3), progress=progress),
        "prt_tables": lambda progress: translucent.Prt(ball, unbuilt, backend="cpu", progress=progress),
        "prt_walks": lambda progress: translucent.Prt(
            ball, marble, walks=2**20, backend="cpu", progress=progress
        ),
        "reference_radiance": lambda progress: translucent.reference_radiance(
            ball, marble, walks=2**24, receivers=[5], progress=progress
        ),
        "irradiance": lambda progress: lit_by_world.irradiance(
            world_samples=translucent.LIMITS["world_samples"], progress=progress
        ),
        "reference_radiosity": lambda progress: translucent.reference_radiosity(
            ball,
            marble,
            rel_tol=translucent.LIMITS["rel_tol_min"],
            max_level=12,
            max_nodes=translucent.LIMITS["reference_nodes"],
            progress=progress,
        ),
        "reference_single_scattering": lambda progress: translucent.reference_single_scattering(
            ball, marble, steps=2**20, progress=progress
        ),
        "splat": lambda progress: translucent.Splat(ball, eps=1e-6, max_grid=4096).radiosity(marble, progress=progress),
    }


NAMES = ["hierarchy", "prt_tables", "prt_walks", "reference_radiance", "irradiance", "reference_radiosity", "reference_single_scattering",
         "splat"]


@pytest.mark.parametrize("name", NAMES)
def test_progress_comes_often_and_false_stops_within_a_second(name, ball, lit_by_world, marble, unbuilt_tables,
                                                                big_ball):
    call = long_calls(ball, lit_by_world, marble, unbuilt_tables, big_ball)[name]
    times, fractions = [], []
    start = time.monotonic()
    stopped_at = None

    def progress(f):
        nonlocal stopped_at
        now = time.monotonic()
        times.append(now)
        fractions.append(f)
        if now - start > RUN_FOR:
            stopped_at = now
            return False
        return True

    with pytest.raises(translucent.Cancelled):
        call(progress)
    returned = time.monotonic()
    assert stopped_at is not None, f"{name} finished before it was stopped: not a long call"
    gaps = np.diff(times)
    assert gaps.max() <= MAX_GAP, f"{name}: progress gaps up to {gaps.max():.2f} s"
    assert returned - stopped_at <= STOP_WITHIN, f"{name}: {returned - stopped_at:.2f} s after False"
    assert all(0.0 <= f <= 1.0 for f in fractions) and fractions == sorted(fractions)


@pytest.mark.parametrize("name", NAMES)
def test_ctrl_c_stops_within_a_second(name, ball, lit_by_world, marble, unbuilt_tables, big_ball):
    call = long_calls(ball, lit_by_world, marble, unbuilt_tables, big_ball)[name]
    sent = []

    def interrupt():
        sent.append(time.monotonic())
        signal.pthread_kill(threading.main_thread().ident, signal.SIGINT)

    timer = threading.Timer(RUN_FOR, interrupt)
    timer.start()
    try:
        with pytest.raises(KeyboardInterrupt):
            call(None)
        returned = time.monotonic()
    finally:
        timer.cancel()
    assert sent, f"{name} finished before Ctrl-C"
    assert returned - sent[0] <= STOP_WITHIN, f"{name}: {returned - sent[0]:.2f} s after Ctrl-C"


def test_ctrl_c_by_os_kill_while_a_progress_callback_is_given(ball, marble):
    """SIGINT to the process (what a terminal's Ctrl-C sends) with a callback running."""
    calls = []
    timer = threading.Timer(RUN_FOR, lambda: os.kill(os.getpid(), signal.SIGINT))
    timer.start()
    start = time.monotonic()
    try:
        with pytest.raises(KeyboardInterrupt):
            translucent.reference_radiance(ball, marble, walks=2**24, receivers=[7], progress=calls.append)
    finally:
        timer.cancel()
    assert time.monotonic() - start <= RUN_FOR + STOP_WITHIN
    assert len(calls) >= 3


def test_an_exception_in_the_callback_stops_the_call_and_is_raised(ball, marble):
    start = time.monotonic()

    def boom(f):
        if time.monotonic() - start > 0.5:
            raise KeyError("from the callback")

    with pytest.raises(KeyError, match="from the callback"):
        translucent.reference_radiance(ball, marble, walks=2**24, receivers=[3], progress=boom)
    assert time.monotonic() - start <= 0.5 + MAX_GAP + STOP_WITHIN


def test_a_progress_that_is_not_callable_is_a_type_error_naming_it(ball, marble):
    with pytest.raises(TypeError, match="progress"):
        translucent.reference_radiance(ball, marble, walks=16, receivers=[3], progress=42)


# ---------------------------------------------------------------- limits


def test_the_limits_are_exported_by_name():
    limits = translucent.LIMITS
    for name in [
        "walks_per_vertex",
        "prt_walks_per_vertex",
        "total_walks",
        "world_samples",
        "area_samples",
        "irradiance_rays",
        "single_steps",
        "rel_tol_min",
        "reference_nodes",
        "prt_samples",
    ]:
        assert limits[name] > 0, name
    assert limits["walks_per_vertex"] == 2**24 and limits["rel_tol_min"] == 1e-6


def refused(call, limit, asked):
    """`call()` is refused at once with ValueError naming `limit` and what was `asked`."""
    start = time.monotonic()
    with pytest.raises(ValueError) as e:
        call()
    took = time.monotonic() - start
    message = str(e.value)
    assert f"limit {limit} " in message and str(asked) in message, message
    assert took < 1.0, f"refused only after {took:.1f} s"


def test_over_limit_requests_are_refused_up_front_naming_the_limit(ball, lit_by_world, marble):
    refused(lambda: translucent.Prt(ball, marble, samples=50_000_000, backend="cpu"), "prt_samples", 50000000)
    refused(lambda: translucent.Prt(ball, marble, walks=2**21, backend="cpu"), "prt_walks_per_vertex", 2**21)
    refused(
        lambda: translucent.reference_radiance(ball, marble, walks=2**25, receivers=[1]), "walks_per_vertex", 2**25
    )
    refused(lambda: lit_by_world.irradiance(world_samples=10**9), "world_samples", 10**9)
    refused(lambda: ball.irradiance(area_samples=2**17), "area_samples", 2**17)
    refused(lambda: translucent.reference_radiosity(ball, marble, rel_tol=1e-9), "rel_tol_min", "1e-9")
    refused(lambda: translucent.reference_radiosity(ball, marble, max_nodes=2**26), "reference_nodes", 2**26)
    refused(lambda: translucent.reference_single_scattering(ball, marble, steps=2**21), "single_steps", 2**21)


def test_total_walks_and_rays_are_bounded_whatever_each_count(marble):
    # 128 x 128 vertices x 3 channels x 2^24 walks: 8e11 walks, each count within its own limit.
    p, t = plane(128, 1.0)
    s = translucent.Scene(p, t)
    s.add_sun((0, 0, -1), 1.0)
    refused(lambda: translucent.reference_radiance(s, marble, walks=2**24, at="vertex"), "total_walks", 3 * 2**24 * 128 * 128)
    # 1100^2 points x 2^20 world rays: 1.27e12 shadow rays, each count within its own limit.
    p, t = plane(1100, 1.0)
    big = translucent.Scene(p, t)
    big.set_world(color=0.5)
    refused(lambda: big.irradiance(world_samples=2**20), "irradiance_rays", 1100 * 1100 * 2**20)


# ---------------------------------------------------------------- shared between threads


def in_threads(work, n=4):
    """Runs `work(i)` in n threads at once; returns (results, errors)."""
    results, errors = [None] * n, []
    barrier = threading.Barrier(n)

    def go(i):
        barrier.wait()
        try:
            results[i] = work(i)
        except Exception as e:  # noqa: BLE001 - the test reports every error
            errors.append(e)

    threads = [threading.Thread(target=go, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return results, errors


def test_one_prt_evaluates_in_many_threads_at_once(marble):
    p, t = plane(21)
    s = translucent.Scene(p, t)
    s.add_sun((0, 0, -1), 1.0)
    prt = translucent.Prt(s, marble, walks=0, backend="cpu")
    alone = prt.radiosity(marble)
    other = marble.with_layers(roughness=0.3)

    def work(i):
        out = []
        for k in range(10):
            out.append(prt.radiance(other if (i + k) % 2 else marble))
            assert prt.last_eval is not None and prt.report["vertices"] == len(p)
        return out

    results, errors = in_threads(work)
    assert not errors, errors
    for i, out in enumerate(results):
        for k, r in enumerate(out):
            if (i + k) % 2 == 0:
                np.testing.assert_allclose(r, prt.radiance(marble), rtol=1e-6)
    np.testing.assert_allclose(prt.radiosity(marble), alone, rtol=1e-6)


def test_one_hierarchy_in_many_threads_evaluates_or_says_it_is_busy(marble):
    p, t = sphere(10, 1.0)
    s = translucent.Scene(p, t)
    s.add_sun((0, 0, -1), 1.0)
    h = translucent.Hierarchy(s, marble, profile="dipole")
    alone = h.radiosity(marble)
    busy = []

    def work(i):
        out = []
        for _ in range(5):
            if i % 2:
                out.append(h.radiosity(marble))
            else:
                try:
                    out.append(h.report["faces"])
                except RuntimeError as e:
                    assert "busy in another thread" in str(e), e
                    busy.append(e)
        return out

    results, errors = in_threads(work)
    assert not errors, errors
    for i, out in enumerate(results):
        for r in out:
            if i % 2:
                np.testing.assert_allclose(r, alone, rtol=1e-5)
            else:
                assert r == len(t)

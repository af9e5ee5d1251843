"""Settling an FMU run until its own convergence check holds (``[steady] settle_rtol``).

A cold run of a lagged FMU (the bundled variant with Øye dynamic inflow and shaft tilt) starts at the
quasi-steady induction of its initial azimuth and relaxes towards its periodic steady state over a few
revolutions. :func:`settled_window` settles revolution by revolution and stops when the averaging window's
halves agree to ``settle_rtol`` (the convergence check of :func:`calib.fmu.windows.convergence_failures`,
tighter), instead of always settling ``settle_revolutions``; the measurements behind the rule are in
``benchmarks/bench_fmu_run.py --settling`` (CHANGELOG, issue 38).
"""

from __future__ import annotations

import numpy as np

from calib.fmu.windows import convergence_failures, window_statistics


def settled_window(sim, t: float, h: float, max_settle: int, n_average: int):
    """Settle revolution by revolution until the averaging window's own check holds at ``steady.settle_rtol``.

    The window is the last ``average_revolutions`` revolutions simulated; after each further revolution
    it moves on by one. It stops at the first window whose two halves agree to ``settle_rtol`` relative to
    max(|mean|, std) on every checked signal (the convergence check at a tighter tolerance), or after
    ``max_settle`` settling steps: then it is the fixed window of ``settle_revolutions`` +
    ``average_revolutions``, sample for sample.

    Parameters
    ----------
    sim : calib.fmu.simulator.Simulator
        Its instance initialized (or restored) at time ``t``.
    t, h : float
        Simulation time and communication step [s].
    max_settle, n_average : int
        Most settling steps and the averaging steps (whole revolutions of ``steps_per_revolution``).

    Returns
    -------
    samples : ndarray, shape (n_average, read_count)
    times : ndarray, shape (n_average,)
        Sample times [s].
    counters : ndarray
        Counter increases over the window.
    t : float
        End time [s].
    settle : int
        Settling steps taken.
    """
    p = sim.plan
    n = p.steady.steps_per_revolution
    revs = n_average // n
    raw = np.empty((max_settle + n_average, p.read_count))
    times = np.empty(max_settle + n_average)
    counters = [sim._counters()]
    names = [s.name for s in p.signals]
    k = 0
    while True:
        for _ in range(n if k >= n_average else n_average):
            sim._step(t, h)
            t += h
            raw[k] = sim._read()
            times[k] = t
            k += 1
            if k % n == 0:
                counters.append(sim._counters())
        settle = k - n_average
        x = sim._signals(raw[settle:k])
        if settle >= max_settle or not np.all(np.isfinite(x[:, list(p.checked)])):
            break
        mean, halves, _ = window_statistics(x, None)
        if not convergence_failures(mean, halves, x, p.steady.settle_rtol, p.checked, names):
            break
    return raw[settle:k], times[settle:k], counters[-1] - counters[-1 - revs], t, settle

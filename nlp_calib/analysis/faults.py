"""Encoder and tracker faults: data no calibration can explain, found by its own inconsistency.

Each interval's encoder increments are checked against the tracker's motion over the same
interval, through the calibrated model: linearising the interval's residual ``e(u)`` in its
inputs gives, per counter encoder, the correction ``c`` (in ticks) that would make the reading
agree with the tracker. For a sound reading ``c`` is noise (tracker noise, timing jitter). A
counter that reads stale for a few samples shows ``+c`` over the stall and ``−c`` when it catches
up: the running sum of the corrections returns. A **fault** is a correction that persists: the
counts over a stretch of records are wrong in total, so every residual window crossing it is
wrong. Kinds:

- ``stall_then_jump``: the counter reads stale, then jumps with the wrong sign (on the real robot,
  the catch-up increment lost 2¹⁶ ticks: a 16-bit counter wrapped in the logger);
- ``reversal``: a single increment against the motion the tracker shows, not made up afterwards;
- ``counter_jump``: counts gained or lost in the direction of motion, not made up afterwards;
- ``tracker_jump``: one tracker pose off the motion of its neighbours (the two intervals around
  it disagree with the encoders in opposite directions).

Genuine reversing, stops and counter wraps are consistent with the tracker and are not flagged.
Stale readings that catch up are counted (``stale``) but harmless to horizon windows.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from nlp_calib.analysis.joint_repair import repair_joints
from nlp_calib.core import poses
from nlp_calib.core.numeric import COUNTER_MODULUS, wrapped_difference
from nlp_calib.logs import Log
from nlp_calib.logs.log import frozen
from nlp_calib.problem import ProblemFunctions, over_columns
from nlp_calib.results.faults import Fault, FaultReport

#: A correction beyond this many robust standard deviations starts a candidate fault...
CANDIDATE_SIGMAS = 6.0
#: ...which is a fault when the running sum of corrections steps by more than this many
#: standard deviations of such steps across its stretch (:data:`PERSIST_INTERVALS` either side),
#: or by more than :data:`AGAINST_SIGMAS` when the reading contradicts the tracker's direction
#: (itself evidence: a sound counter never does).
FAULT_SIGMAS = 6.0
AGAINST_SIGMAS = 4.0
PERSIST_INTERVALS = 10
#: Longest stall a fault's stretch extends back over.
MAX_STALL = 25
#: A 16-bit counter wraps after this many ticks (named in the evidence when the deficit matches).
WRAP_16 = 2**16


def robust_sigma(x: np.ndarray) -> float:
    """1.4826 × the median absolute deviation (a standard deviation that ignores outliers)."""
    x = np.asarray(x, dtype=float)
    x = x[np.isfinite(x)]
    if x.size == 0:
        return float("nan")
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def counter_corrections(e: np.ndarray, de_du: np.ndarray, rows: list[int], scale: np.ndarray) -> np.ndarray:
    """Per interval, the counter increments (ticks) that best explain each residual ``e`` (3, N).

    ``de_du`` is (3, N, n_in); the corrections of the counter ``rows`` solve the weighted least
    squares ``min |e + de_du·c|²`` with each residual component weighted by its robust scatter.
    """
    w = 1.0 / np.maximum([robust_sigma(e[i]) for i in range(3)], 1e-12) ** 2
    G = de_du[:, :, rows]  # (3, N, m)
    A = np.einsum("inj,i,ink->njk", G, w, G)
    b = -np.einsum("inj,i,in->nj", G, w, e)
    A = A + 1e-12 * np.trace(A, axis1=1, axis2=2)[:, None, None] * np.eye(len(rows))
    c = np.linalg.solve(A, b[:, :, None])[:, :, 0]  # (N, m) in input units
    return c * scale[None, :]


def _evidence(
    kind: str, name: str, logged: float, implied: float, noise: float, records: str, unit: str = "ticks"
) -> str:
    deficit = implied - logged
    if unit != "ticks":  # rescaled readings (joint angles): no counter width to name
        text = (
            f"{name} reads {logged:+.4g} {unit} over {records}; the tracker's motion implies "
            f"{implied:+.4g} ± {noise:.2g}: {deficit:+.4g} {unit} unexplained"
        )
        return text + ("; the joint stood still before the jump" if kind == "stall_then_jump" else "")
    text = (
        f"{name} reads {logged:+.0f} ticks over {records}; the tracker's motion implies "
        f"{implied:+.0f} ± {noise:.0f}: {deficit:+.0f} ticks unexplained"
    )
    wraps = round(deficit / WRAP_16)
    if wraps and abs(deficit - wraps * WRAP_16) < 3.0 * max(noise, 1.0):
        text += f" (= {wraps:+d} × 2^16: a 16-bit counter wrapped)"
    return text + ("; the counter was stale before the jump" if kind == "stall_then_jump" else "")


def detect(
    e: np.ndarray,
    de_du: np.ndarray,
    z: np.ndarray,
    logged: np.ndarray,
    counters: Mapping[str, tuple[int, float]],
    time_s: np.ndarray,
    lines: np.ndarray,
    unit: str = "ticks",
) -> FaultReport:
    """Faults among the N intervals whose residuals ``e`` (3, N), ``de_du`` (3, N, n_in) and
    tracker motions ``z`` (3, N) are given.

    ``logged`` holds the inputs (n_in, N); ``counters`` each counter's input row and readings per
    unit, in ``unit`` (``ticks``, or ``rad`` for joints in radians); ``time_s`` and ``lines``
    describe the N + 1 records. Tracker jumps are found first and the intervals around them left
    out of the counters' checks.
    """
    N = e.shape[1]
    jumps = _tracker_jumps(e, z, time_s, lines)
    spoiled = np.zeros(N, dtype=bool)
    for f in jumps:
        spoiled[f.first : f.last + 1] = True
    faults: list[Fault] = list(jumps)
    stale: dict[str, int] = {}
    noise: dict[str, float] = {}
    names = list(counters)
    if N and names:
        rows = [counters[n][0] for n in names]
        scale = np.array([counters[n][1] for n in names])
        corrections = counter_corrections(e[:, ~spoiled], de_du[:, ~spoiled], rows, scale)
        for j, name in enumerate(names):
            ticks = logged[rows[j]] * scale[j]
            c = np.zeros(N)
            c[~spoiled] = corrections[:, j]  # a bad tracker pose says nothing about the counter
            found, n_stale, sigma = _counter_faults(name, ticks, c, time_s, lines, unit)
            faults += found
            stale[name] = n_stale
            noise[name] = sigma
    faults.sort(key=lambda f: (f.first, f.kind))
    return FaultReport(faults=tuple(faults), stale=stale, noise_ticks=noise)


def _level(C: np.ndarray, idx: np.ndarray) -> float:
    """The running sum's level over indices ``idx``: their median (NaN for fewer than two)."""
    return float(np.median(C[idx])) if idx.size >= 2 else float("nan")


def _counter_faults(
    name: str, ticks: np.ndarray, c: np.ndarray, time_s: np.ndarray, lines: np.ndarray, unit: str = "ticks"
) -> tuple[list[Fault], int, float]:
    N = c.size
    implied = ticks + c
    sigma = robust_sigma(c)
    if not np.isfinite(sigma) or sigma <= 0:
        return [], 0, sigma
    # The running sum of the corrections is flat with noise, ramps while the counter reads stale
    # and returns when it catches up, and steps where counts were lost or gained. Its level is
    # read only right after a non-zero reading (no stall pending), as a median over
    # PERSIST_INTERVALS such points before and after a stretch, which a short burst does not move.
    C = np.concatenate([[0.0], np.cumsum(c)])  # C[k] = sum of c over intervals < k
    valid = np.concatenate([[0], np.flatnonzero(ticks != 0) + 1])
    W = PERSIST_INTERVALS
    against = (np.sign(ticks) == -np.sign(implied)) & (ticks != 0) & (np.abs(c) > 3.0 * sigma)
    catch_up = np.zeros(N, dtype=bool)
    catch_up[1:] = (ticks[1:] != 0) & (ticks[:-1] == 0)  # zero readings are judged with their catch-up
    large = (np.abs(c) > CANDIDATE_SIGMAS * sigma) & (ticks != 0)
    candidates: list[int] = np.flatnonzero(against | catch_up | large).tolist()
    firsts = {}
    for k in candidates:
        # The stretch runs back over the stall: readings that stayed put, or caught up only partly
        # (short of the motion, in the fault's direction, by more than 2σ).
        first = k
        while first > 0 and k - first < MAX_STALL:
            prev = first - 1
            if not (ticks[prev] == 0 or (np.sign(c[prev]) == np.sign(c[k]) and abs(c[prev]) > 2.0 * sigma)):
                break
            first = prev
        firsts[int(k)] = int(first)

    accepted: list[tuple[int, int]] = []  # stretches (first, last) of the faults found so far

    def step(k: int) -> float:
        # Levels never reach across a fault already found: it would lend its step to k.
        lo = max((last + 1 for first, last in accepted if last < firsts[k]), default=0)
        hi = min((first for first, last in accepted if first > k), default=N)
        # ``valid`` is sorted: the points in [lo, first] and in [k + 1, hi] are slices of it.
        b0, b1 = np.searchsorted(valid, lo, "left"), np.searchsorted(valid, firsts[k], "right")
        a0, a1 = np.searchsorted(valid, k + 1, "left"), np.searchsorted(valid, hi, "right")
        before = valid[b0:b1][-W:]
        after = valid[a0:a1][:W]
        return _level(C, after) - _level(C, before)

    # The noise of such a step, from steps taken everywhere along the log (faults are few there).
    levels = C[valid]
    if levels.size >= 2 * W:
        medians = np.median(np.lib.stride_tricks.sliding_window_view(levels, W), axis=1)
        step_sigma = max(robust_sigma(medians[W:] - medians[:-W]), sigma)
    else:
        step_sigma = max(robust_sigma(np.array([step(k) for k in candidates])), sigma)
    # The most significant step first, so that the strongest faults bound their neighbours' levels.
    faults: list[Fault] = []
    open_ = list(candidates)
    while open_:
        threshold = np.array([AGAINST_SIGMAS if against[k] else FAULT_SIGMAS for k in open_]) * step_sigma
        score = np.abs([step(k) for k in open_]) / threshold
        if not np.any(score > 1.0):
            break
        k = open_.pop(int(np.nanargmax(score)))
        first = firsts[k]
        accepted.append((first, k))
        total_logged = float(np.sum(ticks[first : k + 1]))
        total_implied = float(np.sum(implied[first : k + 1]))
        open_ = [j for j in open_ if not first <= j <= k and not firsts[j] <= k < j]
        zone_noise = float(sigma * np.sqrt(k + 1 - first))
        kind = "stall_then_jump" if first < k else ("reversal" if against[k] else "counter_jump")
        records = f"records {first}-{k + 1} (lines {lines[first]}-{lines[k + 1]})"
        faults.append(
            Fault(
                kind=kind,
                encoder=name,
                first=first,
                last=k,
                record=k + 1,
                time_s=float(time_s[k + 1]),
                line=int(lines[k + 1]),
                logged=total_logged,
                implied=total_implied,
                noise=zone_noise,
                evidence=_evidence(
                    kind, f"counter {name!r}", total_logged, total_implied, zone_noise, records, unit
                ),
            )
        )
    faulty = np.zeros(N, dtype=bool)
    for f in faults:
        faulty[f.first : f.last + 1] = True
    n_stale = int(np.sum((ticks == 0) & (np.abs(implied) > 3.0 * sigma) & ~faulty))
    return sorted(faults, key=lambda f: f.first), n_stale, sigma


def _tracker_jumps(e: np.ndarray, z: np.ndarray, time_s: np.ndarray, lines: np.ndarray) -> list[Fault]:
    """Tracker poses (one, or two in a row) off the motion both neighbouring intervals show.

    Around a bad pose the residuals of the intervals that meet at it are large, while the residual
    of the merged interval that skips it (tracker motion ``z`` and predicted motion ``h = z·e``
    composed over the intervals) is small.
    """
    N = e.shape[1]
    sig = np.maximum([robust_sigma(e[i]) for i in range(3)], 1e-12)
    size = np.linalg.norm(e / sig[:, None], axis=0)
    Z, H = z.T, poses.compose(z.T, e.T)
    found: list[Fault] = []
    taken = np.zeros(N + 1, dtype=bool)
    big = size >= 2.0 * FAULT_SIGMAS
    for gap in (1, 2):
        # Only poses whose two neighbouring intervals both have large residuals can be off.
        for p in (np.flatnonzero(big[: N - gap] & big[gap:]) + 1).tolist():
            first, last = p - 1, p + gap - 1  # intervals that meet at poses p..p+gap-1
            if taken[p : p + gap].any():
                continue
            z_all, h_all = Z[first], H[first]
            for k in range(first + 1, last + 1):
                z_all, h_all = poses.compose(z_all, Z[k]), poses.compose(h_all, H[k])
            merged = np.linalg.norm(poses.between(z_all, h_all) / (sig * np.sqrt(gap + 1)))
            if merged > 0.3 * min(size[first], size[last]):
                continue
            taken[p : p + gap] = True
            for q in range(p, p + gap):
                off = poses.between(H[q - 1], Z[q - 1]) if q == p else poses.between(Z[q], H[q])
                found.append(
                    Fault(
                        kind="tracker_jump",
                        encoder=None,
                        first=first,
                        last=last,
                        record=q,
                        time_s=float(time_s[q]),
                        line=int(lines[q]),
                        logged=0.0,
                        implied=float(np.hypot(off[0], off[1])),
                        noise=float(np.hypot(sig[0], sig[1])),
                        evidence=(
                            f"the tracker pose at record {q} (line {lines[q]}) is about "
                            f"{np.hypot(off[0], off[1]):.3f} m and {abs(off[2]):.3f} rad off the motion "
                            f"of its neighbours, which agree with the encoders across it"
                        ),
                    )
                )
    return found


def check_log(
    fns: ProblemFunctions,
    params: np.ndarray,
    log: Log,
    inputs: np.ndarray,
    counters: Mapping[str, tuple[int, float]],
) -> FaultReport:
    """The faults of ``log`` (every interval) given calibrated ``params`` and the model ``inputs``."""
    N = inputs.shape[1]
    if N == 0:
        return FaultReport(faults=(), stale={}, noise_ticks={})
    poses = log.T_world_sensor
    z = over_columns(fns.between, poses[:-1].T, poses[1:].T)[0]
    e, de_du = over_columns(fns.interval_residual, np.ravel(np.asarray(params, dtype=float)), inputs, z)
    de_du = de_du.reshape(3, N, inputs.shape[0])
    unit = "rad" if log.header.encoder_units == "radians" else "ticks"
    return detect(e, de_du, z, inputs, counters, log.time_s, log.line_numbers, unit)


def repair(log: Log, report: FaultReport) -> tuple[Log, tuple[str, ...]]:
    """``log`` with the counts of its counter faults corrected, and one line per change.

    A deficit within 3σ of a multiple of 2¹⁶ ticks is corrected by exactly that multiple (a
    wrapped 16-bit counter); any other by the tracker-implied amount, rounded. The correction is
    added to the reading that shows the fault and to every later one, so the total over the
    fault's stretch becomes right; the stalled readings before it are left as they are. Joints in
    radians are corrected by the tracker-implied amount (:mod:`nlp_calib.analysis.joint_repair`).
    """
    if log.joint_stream is not None:
        return repair_joints(log, report)
    ticks = np.array(log.ticks, dtype=np.int64)
    changes = []
    for f in report.counter_faults:
        assert f.encoder is not None
        col = log.header.encoder_index(f.encoder)
        deficit = f.implied - f.logged
        wraps = round(deficit / WRAP_16)
        exact = wraps != 0 and abs(deficit - wraps * WRAP_16) < 3.0 * max(f.noise, 1.0)
        correction = wraps * WRAP_16 if exact else round(deficit)
        before = int(wrapped_difference(ticks[f.record - 1 : f.record + 1, col])[0])
        ticks[f.record :, col] = np.mod(ticks[f.record :, col] + correction, COUNTER_MODULUS)
        how = f"{wraps:+d} × 2^16" if exact else "the tracker-implied amount"
        changes.append(
            f"counter {f.encoder!r} at record {f.record} (line {f.line}): increment {before:+d} → "
            f"{before + correction:+d} ticks ({how}; the tracker's motion implied "
            f"{f.implied - f.logged:+.0f} ± {f.noise:.0f} more over records {f.first}-{f.record})"
        )
    return replace(log, ticks=frozen(ticks)), tuple(changes)

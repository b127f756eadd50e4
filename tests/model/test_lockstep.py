"""The lock-step batch kernels (model.lockstep, model.batch_kernels) against the one-candidate
step (model.kernels.step, bit for bit) and the NumPy reference (model.reference, to 1e-9 m)."""
import math

import numpy as np
import pytest

from stringcast.core import model_ranges
from stringcast.model import kernels
from stringcast.model.lockstep import LANES, atan2_lane
from stringcast.model.reference import hand_at, simulate_reference
from stringcast.model.string_model import _normal, closest_approach_batch, simulate_batch

N, L0, DT, G = 7, 0.03, 1e-4, 9.81
B = LANES + 3                                   # two blocks, the second one part full
HAND_T = np.arange(0.0, 0.05, 0.002)


@pytest.fixture(scope="module")
def batch(settings):
    """B candidates over Table 2 (k_s capped for dt), 3 hand paths mixed, candidate 5 blowing up."""
    lo, hi, _ = model_ranges(settings.model)
    rng = np.random.default_rng(7)
    coeffs = lo * (hi / lo) ** rng.random((B, 10))
    coeffs[:, 0] = np.clip(coeffs[:, 0], 3e3, 1e5)
    coeffs[5] = lo
    coeffs[5, 0] = 1e6                          # the stiffest spring, the softest dampers
    mu = rng.uniform(0.5, 5.0, (B, N))
    mu[5] = 0.003                               # k_s / mu = 3e8 1/s^2: unstable at dt = 1e-4
    t = HAND_T
    hands = np.stack([np.stack([0.8 + a * t + 2 * t**2, 0.2 - 3 * t**2 + a * t, -1.4 + 20 * t**2 - a * t], axis=1)
                      for a in (0.0, 0.5, -1.0)])
    p_init = []
    for h in range(3):
        ang = -np.pi / 2 + np.cumsum(rng.normal(0, 0.3, N))
        seg = L0 * rng.uniform(0.95, 1.05, N)   # tension and compression both occur
        p_init.append(hands[h, 0, :2] + np.cumsum(seg[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1), axis=0))
    hand_idx = rng.integers(0, 3, B)
    hand_idx[:3] = [0, 1, 2]
    return coeffs, mu, hands, hand_idx, np.array(p_init)


def one_candidate(c, mu, hand, p_init, sample_t, psi0, lmax=3 * L0, drag="isotropic"):
    """One candidate by ``kernels.step`` in a Python loop: the per-candidate kernel's algorithm
    (positions on the line of the last step, NaN from a blow-up on)."""
    px, py = p_init[:, 0].copy(), p_init[:, 1].copy()
    vx, vy, fx, fy, ux, uy = np.zeros(N), np.zeros(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    out = np.full((len(sample_t), N, 2), np.nan)
    t0, f, m = sample_t[0], 0, 0
    while f < len(sample_t) and sample_t[f] <= t0:
        out[f] = p_init
        f += 1
    while f < len(sample_t):
        pose, vel = hand_at(HAND_T, hand, t0 + m * DT)
        if not kernels.step(px, py, vx, vy, fx, fy, ux, uy, pose[0], pose[1], vel[0], vel[1], pose[2], vel[2], c,
                            1.0 / mu, L0, psi0, DT, G, lmax, 0.0, _normal(drag)):
            return out, False
        m += 1
        t1 = t0 + m * DT
        while f < len(sample_t) and sample_t[f] <= t1:
            out[f] = np.stack([px - (t1 - sample_t[f]) * vx, py - (t1 - sample_t[f]) * vy], axis=1)
            f += 1
    return out, True


@pytest.mark.parametrize("drag", ["isotropic", "normal"])
def test_batch_is_the_one_candidate_step_bit_for_bit(batch, drag):
    coeffs, mu, hands, hand_idx, p_init = batch
    t = np.arange(0.0, 0.06, 0.0017)            # not a multiple of dt; past hand_t
    pos, ok = simulate_batch(coeffs, mu, HAND_T, hands, hand_idx, p_init, L0, 0.3, DT, t, drag=drag)
    assert pos.shape == (B, len(t), N, 2)
    assert not ok[5] and ok.sum() >= B - 3
    for b in range(B):
        single, ok_b = one_candidate(coeffs[b], mu[b], hands[hand_idx[b]], p_init[hand_idx[b]], t, 0.3, drag=drag)
        assert ok[b] == ok_b
        np.testing.assert_array_equal(pos[b], single)       # NaN from the same sample on


@pytest.mark.parametrize("drag", ["isotropic", "normal"])
def test_batch_matches_numpy_reference(batch, drag):
    coeffs, mu, hands, hand_idx, p_init = batch
    t = np.arange(0.0, 0.06, 0.0017)
    pos, ok = simulate_batch(coeffs, mu, HAND_T, hands, hand_idx, p_init, L0, 0.3, DT, t, drag=drag)
    for b in range(B):
        ref, ok_ref = simulate_reference(coeffs[b], mu[b], HAND_T, hands[hand_idx[b]], p_init[hand_idx[b]],
                                         L0, 0.3, DT, t, drag=drag)
        assert ok[b] == ok_ref
        if ok_ref:
            assert np.max(np.abs(pos[b] - p_init[hand_idx[b]])) > 1e-3     # something happened
            np.testing.assert_allclose(pos[b], ref, rtol=0, atol=1e-9)


def test_a_blow_up_leaves_the_other_candidates_alone(batch):
    coeffs, mu, hands, hand_idx, p_init = batch
    t = np.arange(0.0, 0.06, 0.002)
    pos, ok = simulate_batch(coeffs, mu, HAND_T, hands, hand_idx, p_init, L0, 0.0, DT, t)
    keep = np.arange(B) != 5
    alone, ok_alone = simulate_batch(coeffs[keep], mu[keep], HAND_T, hands, hand_idx[keep], p_init, L0, 0.0, DT, t)
    np.testing.assert_array_equal(pos[keep], alone)          # other lanes and blocks unchanged
    assert np.array_equal(ok[keep], ok_alone) and not ok[5]
    assert np.isnan(pos[5, -1]).all() and not np.isnan(pos[5, 0]).any()
    d, tm, my, ok_c = closest_approach_batch(coeffs, mu, HAND_T, hands, hand_idx, p_init, L0, 0.0, DT, 0.0, 0.06,
                                             [0.9, 0.1])
    d2, tm2, my2, _ = closest_approach_batch(coeffs[keep], mu[keep], HAND_T, hands, hand_idx[keep], p_init, L0,
                                             0.0, DT, 0.0, 0.06, [0.9, 0.1])
    assert not ok_c[5] and d[5] == np.inf and np.isnan(tm[5]) and my[5] == -np.inf
    np.testing.assert_array_equal(np.stack([d[keep], tm[keep], my[keep]]), np.stack([d2, tm2, my2]))


def one_closest(c, mu, hand, p_init, t0, t1, target, target_dt, psi0):
    """Closest approach of one candidate (the per-candidate kernel's algorithm) to target (S, 2)."""
    def target_at(s):
        f = s / target_dt
        if len(target) == 1 or f <= 0.0:
            return target[0]
        i = int(f)
        return target[-1] if i >= len(target) - 1 else target[i] + (f - i) * (target[i + 1] - target[i])

    px, py = p_init[:, 0].copy(), p_init[:, 1].copy()
    vx, vy, fx, fy, ux, uy = np.zeros(N), np.zeros(N), np.empty(N), np.empty(N), np.empty(N), np.empty(N)
    a = np.array([px[-1], py[-1]])
    e = a - target_at(0.0)
    d_min, t_min, min_y = math.sqrt(e[0] * e[0] + e[1] * e[1]), t0, py.min()
    for m in range(int(math.ceil((t1 - t0) / DT - 1e-9))):
        t = t0 + m * DT
        pose, vel = hand_at(HAND_T, hand, t)
        if not kernels.step(px, py, vx, vy, fx, fy, ux, uy, pose[0], pose[1], vel[0], vel[1], pose[2], vel[2], c,
                            1.0 / mu, L0, psi0, DT, G, 3 * L0, 0.0, 0.0):
            return math.inf, math.nan, -math.inf, False
        b, tg = np.array([px[-1], py[-1]]), target_at((m + 1) * DT)
        s = b - a
        s2 = s[0] * s[0] + s[1] * s[1]
        w = min(1.0, max(0.0, ((tg[0] - a[0]) * s[0] + (tg[1] - a[1]) * s[1]) / s2)) if s2 > 0.0 else 0.0
        e = a + w * s - tg
        d = math.sqrt(e[0] * e[0] + e[1] * e[1])
        if d < d_min:
            d_min, t_min = d, t + w * DT
        min_y, a = min(min_y, py.min()), b
    return d_min, t_min, min_y, True


def test_closest_approach_to_moving_targets_is_the_one_candidate_kernel(batch):
    coeffs, mu, hands, hand_idx, p_init = batch
    t0, t1, step = 0.004, 0.05, 0.003
    ts = np.arange(0.0, t1 - t0 + step, step)
    paths = np.stack([np.column_stack([0.9 - 3 * ts, -0.02 + 0.5 * np.sin(60 * ts)]),
                      np.column_stack([0.7 + 3 * ts, -0.1 + ts]),
                      np.repeat([[0.85, 0.05]], len(ts), axis=0)])
    tidx = np.arange(B) % 3
    d, tm, my, ok = closest_approach_batch(coeffs, mu, HAND_T, hands, hand_idx, p_init, L0, 0.2, DT, t0, t1,
                                           paths, target_dt=step, target_idx=tidx)
    for b in range(B):
        one = one_closest(coeffs[b], mu[b], hands[hand_idx[b]], p_init[hand_idx[b]], t0, t1, paths[tidx[b]], step,
                          0.2)
        assert ok[b] == one[3]
        np.testing.assert_array_equal([d[b], tm[b], my[b]], one[:3])
    assert len(np.unique(d[ok])) > B // 2                     # not all met at the start
    assert np.sum(tm[ok] > t0) > B // 2                       # mostly met after the start


def test_atan2_lane_is_the_scalar_atan2():
    rng = np.random.default_rng(3)
    y = rng.normal(size=3000) * 10.0 ** rng.uniform(-6, 3, 3000)
    x = rng.normal(size=3000) * 10.0 ** rng.uniform(-6, 3, 3000)
    edge = [(0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, -0.0), (1.0, 1.0),
            (-1.0, -1.0), (0.66, 1.0), (1.0, 0.66), (1e-300, 1.0), (-1e-300, -1.0)]
    y = np.r_[y, [e[0] for e in edge]]
    x = np.r_[x, [e[1] for e in edge]]
    lane = np.array([atan2_lane(a, b) for a, b in zip(y, x)])
    np.testing.assert_array_equal(lane, [kernels.atan2(a, b) for a, b in zip(y, x)])
    np.testing.assert_array_equal(np.signbit(lane), np.signbit(np.arctan2(y, x)))


def test_the_batch_kernels_cache_is_dropped_when_an_inlined_file_changes(tmp_path):
    """numba keys a cached kernel on its own file's text; the batch kernels inline lockstep and
    kernels, so their cache must go when those change (an old step ran after such an edit)."""
    from types import SimpleNamespace

    from stringcast.model.batch_kernels import drop_stale_cache

    src, cache = tmp_path / "step.py", tmp_path / "cache"
    cache.mkdir()
    fake = SimpleNamespace(_cache=SimpleNamespace(_cache_path=str(cache)))
    compiled = [cache / "bk.f-1.py311.nbi", cache / "bk.f-1.py311.1.nbc"]
    other = cache / "lockstep.g-2.py311.nbi"
    src.write_text("step = 1\n")
    for f in (*compiled, other):
        f.write_bytes(b"x")
    assert drop_stale_cache(fake, [src], "bk")                     # no hash kept yet: dropped
    assert not any(f.exists() for f in compiled) and other.exists()
    for f in compiled:
        f.write_bytes(b"x")
    assert not drop_stale_cache(fake, [src], "bk") and all(f.exists() for f in compiled)   # unchanged: kept
    src.write_text("step = 2\n")
    assert drop_stale_cache(fake, [src], "bk") and not any(f.exists() for f in compiled)
    assert not drop_stale_cache(SimpleNamespace(), [src], "bk")    # no cache (cache=False): nothing to do

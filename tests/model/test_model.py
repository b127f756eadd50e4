import numpy as np
import pytest

from stringcast.core.arm import hand_pose
from stringcast.core import model_ranges
from stringcast.model import (closest_approach_batch, hanging_equilibrium, simulate, simulate_batch,
                              straight_hanging)
from stringcast.model.reference import simulate_reference

N, L0 = 10, 0.03
DT = 1e-4


@pytest.fixture(scope="module")
def ranges(settings):
    lo, hi, mu_range = model_ranges(settings.model)
    return lo, hi


@pytest.fixture(scope="module")
def mid(ranges):
    """Log-midpoint of Table 2's ranges."""
    lo, hi = ranges
    return np.sqrt(lo * hi)


def swing(arm, T=0.6, hold=0.3, rate=500.0, dq=(0.5, 0.8, 0.8)):
    """A real swinging hand motion: minimum-jerk joint move through the arm's FK."""
    t = np.arange(0.0, T + hold, 1.0 / rate)
    s = np.clip(t / T, 0, 1)
    s = 10 * s**3 - 15 * s**4 + 6 * s**5
    q = np.array([0.8, -1.2, -0.6]) + s[:, None] * np.asarray(dq)
    return t, hand_pose(arm, q)


def hanging(coeffs, hand0, n=N, mu=None):
    mu = np.ones(n) if mu is None else mu
    return hanging_equilibrium(coeffs, mu, hand0, L0, 0.0, n, tol=1e-5)


def test_string_at_rest_stays_at_rest(mid):
    for phi in (-np.pi / 2, -np.pi / 2 + 0.4):           # straight, and pulled by the hand spring
        hand0 = np.array([0.9, 0.2, phi])
        p_eq = hanging_equilibrium(mid, np.ones(N), hand0, L0, 0.0, N, tol=1e-7)
        seg = np.linalg.norm(np.diff(np.vstack([hand0[:2], p_eq]), axis=0), axis=1)
        assert np.all(seg > L0)                            # stretched by its weight
        t = np.arange(0.0, 1.0, 0.01)
        pos, ok = simulate(mid, np.ones(N), [0.0], hand0[None], p_eq, L0, 0.0, DT, t)
        assert ok
        assert np.max(np.abs(pos - p_eq)) < 1e-5
    # straight down from a downward hand: the stretched straight chain is exact
    assert np.max(np.abs(p_eq - straight_hanging(mid, np.ones(N), hand0, L0, N))) > 0
    p_s = straight_hanging(mid, np.ones(N), np.array([0.9, 0.2, -np.pi / 2]), L0, N)
    pos, ok = simulate(mid, np.ones(N), [0.0], [[0.9, 0.2, -np.pi / 2]], p_s, L0, 0.0, DT, t)
    assert ok and np.max(np.abs(pos - p_s)) < 1e-9


def _energy(p, v, hand0, coeffs, mu, psi0):
    k_s, _, k_h, _, k_sh, _, _, _, k_ph, _ = coeffs
    assert k_h == k_sh
    q = np.vstack([hand0[:2], p])
    seg = np.diff(q, axis=0)
    l = np.linalg.norm(seg, axis=1)
    ang = np.arctan2(seg[:, 1], seg[:, 0])
    theta = np.angle(np.exp(1j * np.diff(ang)))
    th0 = np.angle(np.exp(1j * (ang[0] - hand0[2] - psi0)))
    return (0.5 * np.sum(mu * np.sum(v**2, axis=1)) + 0.5 * k_s * np.sum((l - L0) ** 2)
            + 0.5 * k_h * np.sum(theta**2) + 0.5 * k_ph * th0**2), np.max(np.abs(theta))


def test_bent_string_straightens_without_gravity_and_loses_energy():
    coeffs = np.array([1e4, 2.0, 1.0, 0.3, 1.0, 0.3, 1.0, 1e-3, 1e-2, 1e-2])
    mu = np.linspace(1.0, 2.0, N)
    hand0 = np.array([0.0, 0.0, 0.0])
    ang = 0.25 * np.arange(N)                              # each node bent by 0.25 rad
    p0 = np.cumsum(L0 * np.stack([np.cos(ang), np.sin(ang)], axis=1), axis=0)
    # pairs of samples one step apart give the velocity of the step exactly
    t = np.repeat(np.arange(0.0, 3.0, 0.05), 2) + np.tile([0.0, DT], 60)
    pos, ok = simulate(coeffs, mu, [0.0], hand0[None], p0, L0, 0.0, DT, t, g=0.0)
    assert ok
    p, v = pos[1::2], (pos[1::2] - pos[0::2]) / DT
    energy, bend = np.array([_energy(p[k], v[k], hand0, coeffs, mu, 0.0) for k in range(len(p))]).T
    assert bend[0] == pytest.approx(0.25, abs=1e-3)
    assert bend[-1] < 0.02                                  # straight again
    assert energy[-1] < 0.03 * energy[0]
    assert np.all(np.diff(energy) < 1e-3 * energy[0])       # never gains energy (to O(dt))


def test_halving_dt_changes_the_tip_path_little(campaign, mid):
    hand_t, hand = swing(campaign.arm)
    p0 = hanging(mid, hand[0])
    t = np.arange(0.0, 0.9, 0.002)
    tips = []
    for dt in (1e-4, 5e-5, 2.5e-5):
        pos, ok = simulate(mid, np.ones(N), hand_t, hand, p0, L0, 0.0, dt, t)
        assert ok
        tips.append(pos[:, -1])
    assert np.ptp(tips[0][:, 0]) > 0.2                      # it really swings
    d1 = np.max(np.linalg.norm(tips[0] - tips[1], axis=1))
    d2 = np.max(np.linalg.norm(tips[1] - tips[2], axis=1))
    assert d1 < 2e-3
    assert d2 < 0.75 * d1                                   # converging as dt shrinks


def test_heavier_point_falls_the_same():
    """The hand falls freely (Euler-discrete free fall), the unstressed string with it.

    Gravity is not divided by mu, so the string keeps its shape and every point falls
    exactly like the hand whatever its mass (damping off: the hand's velocity is
    piecewise constant, a point's is not)."""
    coeffs = np.array([1e5, 0.0, 0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 5e-3, 0.0])
    m = np.arange(3001)
    hand_t = m * DT
    fall = -9.81 * DT**2 * m * (m + 1) / 2
    hand = np.stack([np.zeros_like(fall), fall, np.zeros_like(fall)], axis=1)
    p0 = np.stack([L0 * np.arange(1, N + 1), np.zeros(N)], axis=1)   # horizontal, at rest length
    t = hand_t[::100]
    plain, ok1 = simulate(coeffs, np.ones(N), hand_t, hand, p0, L0, 0.0, DT, t)
    heavy_mu = np.ones(N)
    heavy_mu[-1], heavy_mu[4] = 50.0, 0.2
    heavy, ok2 = simulate(coeffs, heavy_mu, hand_t, hand, p0, L0, 0.0, DT, t)
    assert ok1 and ok2
    expected = p0[None] + np.stack([np.zeros_like(t), fall[::100]], axis=1)[:, None]
    assert fall[-1] < -0.4
    np.testing.assert_allclose(plain, expected, atol=1e-9)
    np.testing.assert_allclose(heavy, expected, atol=1e-9)


def test_heavier_tip_swings_differently(campaign, mid):
    hand_t, hand = swing(campaign.arm)
    t = np.arange(0.0, 0.9, 0.002)
    paths = []
    for tip_mu in (1.0, 10.0):
        mu = np.ones(N)
        mu[-1] = tip_mu
        pos, ok = simulate(mid, mu, hand_t, hand, hanging(mid, hand[0], mu=mu), L0, 0.0, DT, t)
        assert ok
        paths.append(pos[:, -1])
    assert np.max(np.linalg.norm(paths[0] - paths[1], axis=1)) > 0.01


def test_stiffest_table2_corner_is_stable_at_dt_1e4(campaign, ranges):
    lo, hi = ranges
    hand_t, hand = swing(campaign.arm)
    t = np.arange(0.0, 0.9, 0.005)
    p0 = straight_hanging(hi, np.full(N, 0.1), hand[0], L0, N)
    pos, ok = simulate(hi, np.full(N, 0.1), hand_t, hand, p0, L0, 0.0, DT, t)
    assert ok and np.all(np.isfinite(pos))
    seg = np.linalg.norm(np.diff(pos, axis=1), axis=-1)
    assert np.max(seg) < 1.05 * L0
    assert np.ptp(pos[:, -1, 0]) > 0.1
    # every coefficient at a random end of its range, k_s = 1e6, masses 0.1 or 100
    # side by side: numerically finite everywhere (stretch limit off to see only that)
    rng = np.random.default_rng(1)
    B = 32
    C = np.where(rng.random((B, 10)) < 0.5, lo, hi)
    C[:, 0] = hi[0]
    MU = np.where(rng.random((B, N)) < 0.5, 0.1, 100.0)
    pos, ok = simulate_batch(C, MU, hand_t, hand[None], np.zeros(B, np.int64), p0[None], L0, 0.0,
                             DT, t, max_stretch=1e3)
    assert ok.all() and np.all(np.isfinite(pos))


def test_blow_up_gives_ok_false_not_an_exception(campaign, ranges):
    lo, hi = ranges
    hand_t, hand = swing(campaign.arm)
    c = lo.copy()
    c[0] = 1e6
    p0 = straight_hanging(c, np.ones(N), hand[0], L0, N)
    t = np.arange(0.0, 0.5, 0.01)
    pos, ok = simulate(c, np.ones(N), hand_t, hand, p0, L0, 0.0, 5e-3, t)
    assert not ok and np.isnan(pos[-1]).all()
    d, tm, my, ok = closest_approach_batch(c, np.ones(N), hand_t, hand[None], [0], p0[None], L0,
                                           0.0, 5e-3, 0.0, 0.5, [1.2, 0.3])
    assert not ok[0] and d[0] == np.inf and my[0] == -np.inf
    with pytest.raises(RuntimeError, match="blew up"):
        hanging_equilibrium(c, np.ones(N), hand[0], L0, 0.0, N, dt=5e-3)
    with pytest.raises(RuntimeError, match="still"):
        hanging_equilibrium(c, np.ones(N), hand[0] + [0, 0, 1.0], L0, 0.0, N, t_max=0.01)


def _random_case(ranges, seed, n=6):
    lo, hi = ranges
    rng = np.random.default_rng(seed)
    coeffs = lo * (hi / lo) ** rng.random(10)
    coeffs[0] = min(coeffs[0], 1e5)
    mu = rng.uniform(0.5, 5.0, n)
    hand_t = np.arange(0.0, 0.04, 0.002)
    hand = np.stack([0.8 + 0.3 * hand_t + 2 * hand_t**2, 0.2 - 3 * hand_t**2,
                     -1.4 + 20 * hand_t**2], axis=1)
    ang = -np.pi / 2 + np.cumsum(rng.normal(0, 0.3, n))
    seg = L0 * rng.uniform(0.95, 1.05, n)                  # tension and compression both occur
    p0 = hand[0, :2] + np.cumsum(seg[:, None] * np.stack([np.cos(ang), np.sin(ang)], 1), axis=0)
    return coeffs, mu, hand_t, hand, p0


def test_numba_matches_numpy_reference(ranges):
    t = np.arange(0.0, 0.06, 0.0017)                       # not a multiple of dt; past hand_t
    for seed in range(3):
        coeffs, mu, hand_t, hand, p0 = _random_case(ranges, seed)
        pos, ok = simulate(coeffs, mu, hand_t, hand, p0, L0, 0.3, DT, t)
        ref, ok_ref = simulate_reference(coeffs, mu, hand_t, hand, p0, L0, 0.3, DT, t)
        assert ok and ok_ref
        assert np.max(np.abs(pos - p0)) > 1e-3                  # something happened
        np.testing.assert_allclose(pos, ref, rtol=0, atol=1e-9)


def test_batch_equals_single(ranges):
    cases = [_random_case(ranges, s) for s in range(3)]
    hand_t = cases[0][2]
    hands = np.stack([cases[0][3], cases[1][3] + [0.1, 0.0, 0.2]])
    p_init = np.stack([cases[0][4], cases[1][4] + [0.1, 0.0]])
    idx = np.array([0, 1, 1])
    t = np.arange(0.0, 0.05, 0.002)
    C = np.stack([c[0] for c in cases])
    MU = np.stack([c[1] for c in cases])
    pos, ok = simulate_batch(C, MU, hand_t, hands, idx, p_init, L0, 0.0, DT, t)
    assert pos.shape == (3, len(t), 6, 2) and ok.all()
    for b in range(3):
        single, ok_b = simulate(C[b], MU[b], hand_t, hands[idx[b]], p_init[idx[b]], L0, 0.0, DT, t)
        assert ok_b
        np.testing.assert_allclose(pos[b], single, rtol=0, atol=1e-12)


def test_closest_approach_matches_dense_simulation(campaign, mid):
    hand_t, hand = swing(campaign.arm)
    hands = np.stack([hand, hand + [0.05, -0.02, 0.1]])
    p_init = np.stack([hanging(mid, h[0]) for h in hands])
    target = np.array([1.2, 0.3])
    t0, t1 = 0.1, 0.8
    d, tm, my, ok = closest_approach_batch(mid, np.ones(N), hand_t, hands, [0, 1], p_init, L0,
                                           0.0, DT, t0, t1, target)
    assert ok.all() and d.shape == (2,)
    t = t0 + DT * np.arange(round((t1 - t0) / DT) + 1)
    for b in range(2):
        pos, _ = simulate(mid, np.ones(N), hand_t, hands[b], p_init[b], L0, 0.0, DT, t)
        a, s = pos[:-1, -1], np.diff(pos[:, -1], axis=0)
        w = np.clip(np.sum((target - a) * s, 1) / np.sum(s * s, 1), 0, 1)
        dist = np.linalg.norm(a + w[:, None] * s - target, axis=1)
        k = np.argmin(dist)
        assert d[b] == pytest.approx(dist[k], abs=1e-9)
        assert tm[b] == pytest.approx(t[k] + w[k] * DT, abs=1e-9)
        assert my[b] == pytest.approx(pos[..., 1].min(), abs=1e-9)
        assert d[b] <= np.min(np.linalg.norm(pos[:, -1] - target, axis=1))


def test_closest_approach_to_a_moving_target(campaign, mid):
    """A target path (the residual-corrected target) is met where the dense simulation says;
    a path that stands still gives the fixed target's result exactly."""
    hand_t, hand = swing(campaign.arm)
    p_init = hanging(mid, hand[0])[None]
    t0, t1, step = 0.1, 0.8, 0.01
    ts = t0 + step * np.arange(round((t1 - t0) / step) + 1)
    path = np.column_stack([1.2 - 0.3 * (ts - t0), 0.3 + 0.2 * np.sin(6 * ts)])
    still = np.repeat([[1.2, 0.3]], len(ts), axis=0)
    d, tm, _, ok = closest_approach_batch(mid, np.ones(N), hand_t, hand[None], [0, 0], p_init, L0, 0.0, DT, t0, t1,
                                          np.stack([path, still]), target_dt=step, target_idx=[0, 1])
    fixed = closest_approach_batch(mid, np.ones(N), hand_t, hand[None], [0], p_init, L0, 0.0, DT, t0, t1,
                                   np.array([1.2, 0.3]))
    assert ok.all() and d[1] == fixed[0][0] and tm[1] == fixed[1][0]
    t = t0 + DT * np.arange(round((t1 - t0) / DT) + 1)
    pos, _ = simulate(mid, np.ones(N), hand_t, hand, p_init[0], L0, 0.0, DT, t)
    tgt = np.column_stack([np.interp(t, ts, path[:, 0]), np.interp(t, ts, path[:, 1])])
    dist = np.linalg.norm(pos[:, -1] - tgt, axis=1)
    assert d[0] <= dist.min() + 1e-9            # segments, not only the substep points
    assert d[0] == pytest.approx(dist.min(), abs=2e-3)  # within a substep's travel of the tip
    assert abs(tm[0] - t[np.argmin(dist)]) <= 2 * DT
    assert abs(d[0] - d[1]) > 0.01              # the moving target really moved the answer
    with pytest.raises(ValueError, match="target_dt"):
        closest_approach_batch(mid, np.ones(N), hand_t, hand[None], [0], p_init, L0, 0.0, DT, t0, t1, path[None])


def test_bad_inputs_raise_value_error(mid):
    hand = np.zeros((1, 2, 3))
    p = np.zeros((1, N, 2)) + np.arange(N)[:, None] * [0, -L0]
    args = dict(hand_t=[0.0, 1.0], hand=hand, hand_idx=[0], p_init=p, l0=L0, psi0=0.0, dt=DT,
                sample_t=[0.0, 0.1])
    with pytest.raises(ValueError, match="coeffs"):
        simulate_batch(np.ones((1, 9)), np.ones((1, N)), **args)
    with pytest.raises(ValueError, match="mu"):
        simulate_batch(mid[None], np.ones((1, N + 1)), **args)
    with pytest.raises(ValueError, match="mu"):
        simulate_batch(mid[None], -np.ones((1, N)), **args)
    with pytest.raises(ValueError, match="hand_idx"):
        simulate_batch(mid[None], np.ones((1, N)), **dict(args, hand_idx=[1]))
    with pytest.raises(ValueError, match="hand_t"):
        simulate_batch(mid[None], np.ones((1, N)), **dict(args, hand_t=[1.0, 0.0]))
    with pytest.raises(ValueError, match="sample_t"):
        simulate_batch(mid[None], np.ones((1, N)), **dict(args, sample_t=[0.1, 0.0]))


def test_kernel_atan2_matches_libm():
    """The kernel's atan2 is within one ulp of libm's (``math.atan2``, as its docstring says), signs
    and zeros included. Not NumPy's arctan2: with AVX-512 that is SVML's, itself 1 ulp off libm's on
    ~2 % of these inputs, so the two could sit 2 ulp apart on one machine and not on another."""
    import math

    from stringcast.model.kernels import atan2

    rng = np.random.default_rng(3)
    y = rng.normal(size=3000) * 10.0 ** rng.uniform(-6, 3, 3000)
    x = rng.normal(size=3000) * 10.0 ** rng.uniform(-6, 3, 3000)
    edge = [(0.0, 1.0), (0.0, -1.0), (-0.0, -1.0), (1.0, 0.0), (-1.0, 0.0), (1.0, 1.0), (-1.0, -1.0),
            (0.66, 1.0), (1.0, 0.66), (1e-300, 1.0), (np.inf, 1.0)]
    y = np.r_[y, [e[0] for e in edge]]
    x = np.r_[x, [e[1] for e in edge]]
    ours = np.array([atan2(a, b) for a, b in zip(y, x)])
    libm = np.array([math.atan2(a, b) for a, b in zip(y, x)])
    assert np.all(np.abs(ours - libm) <= np.spacing(np.abs(libm)))       # one ulp (1.0 measured, 200 000 pairs)
    assert np.array_equal(np.signbit(ours), np.signbit(libm))


@pytest.mark.parametrize("along", [True, False])
def test_normal_drag_spares_motion_along_the_string(mid, along):
    """``model.drag: normal`` (docs/string_model.md, "Air drag"): a straight string carried along its own
    axis, no gravity, moves as it does without any drag, where the isotropic (paper's) drag holds it
    back; carried broadside (it swings about the grasp), the normal law drags it, less than the isotropic."""
    coeffs = mid.copy()
    coeffs[0] = 1e5                                        # stiff segments
    hand_t = np.arange(0.0, 0.101, 0.002)
    hand = np.zeros((len(hand_t), 3))
    hand[:, 0 if along else 1] = 2.0 * hand_t              # the hand moves at 2 m/s from t = 0
    hand[:, 2] = np.pi                                     # the string leaves the gripper along -x
    p0 = np.stack([-L0 * np.arange(1, N + 1), np.zeros(N)], axis=1)
    t = np.linspace(0.0, 0.1, 11)

    def run(drag, C):
        c = coeffs.copy()
        c[6] = c[7] = C                                    # linear and quadratic drag
        pos, ok = simulate(c, np.ones(N), hand_t, hand, p0, L0, 0.0, DT, t, g=0.0, drag=drag)
        assert ok
        return pos
    free = run("normal", 0.0)
    gap = {drag: np.abs(run(drag, 1.0) - free).max() for drag in ("isotropic", "normal")}
    if along:
        assert gap["normal"] < 1e-9 and gap["isotropic"] > 1e-3
    else:                                                  # the part of the swing across the string is dragged
        assert 1e-3 < gap["normal"] < gap["isotropic"]


def test_normal_drag_reference_drops_only_the_tangential_velocity(mid):
    """The NumPy reference's drag term: velocity along a straight string feels nothing under the normal
    law, velocity across it the same force as the isotropic law's."""
    from stringcast.model.reference import accelerations
    coeffs = mid.copy()
    coeffs[6], coeffs[7] = 0.5, 2.0
    p = np.stack([L0 * np.arange(1, N + 1), np.zeros(N)], axis=1)      # straight along +x from the hand
    for v_dir, expect_zero in (((1.0, 0.0), True), ((0.0, 1.0), False)):
        v = np.tile(v_dir, (N, 1)) * 1.5
        hand_vel = np.array([*v[0], 0.0])
        a_n, _ = accelerations(p, v, np.zeros(3), hand_vel, coeffs, np.ones(N), L0, 0.0, DT, 0.0, "normal")
        a_i, _ = accelerations(p, v, np.zeros(3), hand_vel, coeffs, np.ones(N), L0, 0.0, DT, 0.0, "isotropic")
        drag = -(0.5 + 2.0 * 1.5) * v
        np.testing.assert_allclose(a_i, drag, atol=1e-9)
        np.testing.assert_allclose(a_n, 0.0 if expect_zero else drag, atol=1e-9)


def test_a_blown_up_candidate_is_run_again_at_half_the_step(campaign, ranges, mid):
    """model.blowup_halvings: a candidate that blows up at dt only because dt is too long for it runs
    again at dt / 2 (up to h times) and then equals a plain run at the first step it survives; one that
    blows up at every step stays ok = False; the others are untouched, and h = 0 is the plain run."""
    lo, hi = ranges
    hand_t, hand = swing(campaign.arm)
    stiff = lo.copy()
    stiff[0] = 1e6      # k_s = 1e6 N/m/kg, mu = 1: 2 sqrt(k_s) dt = 8 at 2 ms (unstable), 0.5 at 0.25 ms
    C = np.stack([stiff, mid])
    p0 = straight_hanging(mid, np.ones(N), hand[0], L0, N)
    t = np.arange(0.0, 0.5, 0.01)
    dt, target = 2e-3, [1.2, 0.3]
    args = (C, np.ones((2, N)), hand_t, hand[None], np.zeros(2, np.int64), p0[None], L0, 0.0)
    plain = simulate_batch(*args, dt, t)
    assert list(plain[1]) == [False, True]
    same = simulate_batch(*args, dt, t, halvings=0)
    assert np.array_equal(same[0], plain[0], equal_nan=True) and np.array_equal(same[1], plain[1])
    # the stiff candidate alone, at dt / 2, dt / 4, dt / 8: the first step it survives
    runs = [simulate(stiff, np.ones(N), hand_t, hand, p0, L0, 0.0, dt / 2**h, t) for h in (1, 2, 3)]
    first = next(run for run in runs if run[1])
    pos, ok = simulate_batch(*args, dt, t, halvings=3)
    assert ok.all() and np.array_equal(pos[0], first[0]) and np.array_equal(pos[1], plain[0][1])
    h = 1 + [run[1] for run in runs].index(True)
    d, tm, my, ok = closest_approach_batch(C, np.ones((2, N)), hand_t, hand[None], [0, 0], p0[None], L0, 0.0,
                                           dt, 0.0, 0.5, target, halvings=3)
    ref = closest_approach_batch(stiff, np.ones(N), hand_t, hand[None], [0], p0[None], L0, 0.0, dt / 2**h, 0.0,
                                 0.5, target)
    assert ok.all() and (d[0], tm[0], my[0]) == (ref[0][0], ref[1][0], ref[2][0])
    # a string stretched past max_stretch at every step stays blown up
    _, ok = simulate_batch(*args, dt, t, halvings=2, max_stretch=1.0001)
    assert not ok.any()
    for bad in (-1, 1.5, True):
        with pytest.raises(ValueError, match="halvings"):
            simulate_batch(*args, dt, t, halvings=bad)

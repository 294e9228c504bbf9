"""keyframes.interval_means: the interval average of a sampled rate signal and its 1-sigma."""
import numpy as np
import pytest

from odomgraph.estimators.keyframes import interval_means


@pytest.fixture
def irregular():
    rng = np.random.default_rng(1)
    ts = np.sort(rng.uniform(0, 10, 60))                          # irregular samples, with gaps
    tk = np.sort(np.concatenate([[-0.5, 10.5], rng.uniform(0, 10, 20)]))   # some intervals hold no sample
    return rng, ts, tk


def test_mean_is_the_exact_integral_of_the_linear_interpolant(irregular):
    _, ts, tk = irregular
    z = np.sin(ts) + 0.1 * ts
    m, _, n = interval_means(tk, ts, z, 0.01, 0.3)
    for k in range(len(tk) - 1):
        tt = np.linspace(tk[k], tk[k + 1], 200001)
        ref = np.trapezoid(np.interp(tt, ts, z), tt) / (tk[k + 1] - tk[k])   # np.interp holds the ends
        assert m[k, 0] == pytest.approx(ref, abs=1e-8)
    assert n.sum() == 60 and (n == 0).any()


def test_noise_sigma_follows_the_integration_weights(irregular):
    _, ts, tk = irregular
    E = np.eye(len(ts))
    W = np.stack([interval_means(tk, ts, E[:, j], 0.0, 0.0)[0][:, 0] for j in range(len(ts))], 1)
    _, sd, _ = interval_means(tk, ts, np.zeros(len(ts)), 0.01, 0.0)
    ok = np.isfinite(sd[:, 0])
    assert ok.sum() >= len(tk) - 3
    np.testing.assert_allclose(sd[ok, 0], 0.01 * np.sqrt((W[ok] ** 2).sum(1)), rtol=1e-12)


def test_interpolation_sigma_matches_a_random_walk_monte_carlo(irregular):
    rng, ts, tk = irregular
    dt, q = 1e-3, 0.3
    tf = np.arange(-1.0, 11.5, dt)
    errs = []
    for _ in range(600):
        w = np.cumsum(rng.normal(size=tf.size)) * q * np.sqrt(dt)
        m, _, _ = interval_means(tk, ts, np.interp(ts, tf, w), 0.0, q)
        c = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)])
        errs.append(m[:, 0] - (np.interp(tk[1:], tf, c) - np.interp(tk[:-1], tf, c)) / np.diff(tk))
    _, sd, _ = interval_means(tk, ts, np.zeros(len(ts)), 0.0, q)
    ok = np.isfinite(sd[:, 0])
    ratio = np.std(errs, 0)[ok] / sd[ok, 0]
    # 600 draws: the sample std is within ~3 % of the truth (1 sigma); allow 4.5 sigma
    assert np.all(np.abs(ratio - 1) < 0.13), ratio


def test_no_data_gives_an_infinite_sigma():
    ts = np.array([2.0, 2.1, 2.2])
    tk = np.array([0.0, 1.0, 2.05, 2.15, 3.0, 4.0])
    _, sd, n = interval_means(tk, ts, np.ones(3), 0.01, 0.3)
    assert np.isinf(sd[[0, 4], 0]).all()                          # before the first / after the last sample
    assert np.isfinite(sd[1:4, 0]).all() and n.tolist() == [0, 1, 1, 1, 0]


def test_causal_means_read_no_sample_after_the_interval(irregular):
    rng, ts, tk = irregular
    z = rng.normal(size=len(ts))
    m, sd, n = interval_means(tk, ts, z, 0.01, 0.3, causal=True)
    for k in range(len(tk) - 1):
        later = ts > tk[k + 1]
        z2 = z.copy()
        z2[later] = 1e3                                          # the future changes...
        m2, sd2, _ = interval_means(tk, ts, z2, 0.01, 0.3, causal=True)
        assert m2[k, 0] == m[k, 0] or not np.isfinite(sd[k, 0])  # ...interval k does not
        assert sd2[k, 0] == sd[k, 0]
    # held tails cost variance: causal sigma is never below the two-sided one
    _, sd_two, _ = interval_means(tk, ts, z, 0.01, 0.3)
    ok = np.isfinite(sd[:, 0])
    assert np.all(sd[ok, 0] >= sd_two[ok, 0] - 1e-15) and ok.sum() == (n > 0).sum()


def test_a_long_gap_between_keyframes_gives_the_same_answer_without_padding_every_row():
    rng = np.random.default_rng(5)
    ts = np.arange(0.0, 200.0, 0.04)                               # 25 Hz gyro
    z = np.sin(0.3 * ts) + rng.normal(0, 0.01, ts.size)
    tk = np.concatenate([np.arange(0.0, 100.0, 0.2), np.arange(160.0, 199.9, 0.2)])   # 60 s encoder gap
    m, sd, n = interval_means(tk, ts, z, 0.01, 0.3)
    wide = np.flatnonzero(np.diff(tk) > 1.0)
    assert wide.size == 1 and n[wide[0]] > 1400
    # each row alone equals the same row computed with the others
    for k in (0, 250, wide[0], wide[0] + 1, len(tk) - 2):
        m1, sd1, _ = interval_means(tk[k:k + 2], ts, z, 0.01, 0.3)
        assert m1[0, 0] == pytest.approx(m[k, 0], abs=1e-12) and sd1[0, 0] == pytest.approx(sd[k, 0], rel=1e-12)

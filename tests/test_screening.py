"""diagnose's statistics (gecgen/loop/screening.py) against plain least squares on the full rows.

screen() sums each pose's rows before its products and Folded cross-validates from per-fold Gram
matrices; both must give what fitting the explicit columns J_e[:, e] * f(pose) by lstsq gives."""
import numpy as np
import pytest

from gecgen.loop.screening import FOLDS, Candidate, Folded, basis, columns, folds, screen


@pytest.fixture(scope="module")
def system():
    """A random linear system of 40 poses x 3 targets: H (360, 6), the residual orthogonal to
    it, J_e (360, 4) and two candidates; the residual holds one of them on error 2."""
    rng = np.random.default_rng(3)
    P, k, ne = 40, 6, 4
    rows_pose = np.repeat(np.arange(P), 9)
    H = rng.normal(size=(9 * P, k))
    J = rng.normal(size=(9 * P, ne))
    cands = [Candidate("polynomial", ("q1",), ("q1", "q1**2"), rng.normal(size=(P, 2))),
             Candidate("fourier", ("q2",), ("s", "c", "t"), rng.normal(size=(P, 3)))]
    Q = np.linalg.qr(H)[0]
    r = 0.01 * rng.normal(size=9 * P) + columns(J, cands[1], 2, rows_pose) @ np.array([0.003, -0.002, 0.001])
    r -= Q @ (Q.T @ r)
    return rows_pose, H, J, Q, r, cands, folds(P, rng)


def _projected(Q, X):
    return X - Q @ (Q.T @ X)


def test_screen_drops_and_fitted_effects_equal_least_squares_on_the_explicit_columns(system):
    rows_pose, H, J, Q, r, cands, _ = system
    base = basis(H, [np.linalg.qr(H[:100], mode="r"), np.linalg.qr(H[100:], mode="r")])  # Q never formed
    hits = screen(J, rows_pose, r, base, float(r @ r) / (len(r) - H.shape[1]), cands, [0, 1, 2, 3])
    assert hits and (hits[0].candidate, hits[0].error) == (1, 2)
    assert [h.log_p for h in hits] == sorted(h.log_p for h in hits)
    for h in hits:
        X = _projected(Q, columns(J, cands[h.candidate], h.error, rows_pose))
        beta = np.linalg.lstsq(X, r, rcond=None)[0]
        assert h.drop == pytest.approx(float(np.sum((X @ beta) ** 2)), rel=1e-9)
        assert np.allclose(h.fitted, X @ beta, rtol=0, atol=1e-12)


def test_screen_refuses_rows_of_one_pose_apart(system):
    rows_pose, H, J, Q, r, cands, _ = system
    shuffled = np.r_[rows_pose[1:], rows_pose[:1]]
    with pytest.raises(ValueError, match="adjacent"):
        screen(J, shuffled, r, basis(Q, [np.eye(Q.shape[1])]), 1e-4, cands, [0])


def test_folded_cross_validation_equals_lstsq_per_fold(system):
    rows_pose, H, J, Q, r, cands, fold = system
    fs = Folded(H, r, rows_pose, fold)
    extra = columns(J, cands[1], 2, rows_pose)
    for X in (H, np.column_stack([H, extra])):
        sq = 0.0
        for f in range(FOLDS):
            test = fold[rows_pose] == f
            dc = np.linalg.lstsq(X[~test], r[~test], rcond=None)[0]
            sq += np.sum((r[test] - X[test] @ dc) ** 2)
            if X is H:  # the fold's training basis projects as lstsq's residual does
                assert np.allclose(fs.basis(f).residual(r[fs.training(f)]), r[~test] - X[~test] @ dc, rtol=0, atol=1e-12)
            else:
                assert fs.held_out_sq(f, extra) == pytest.approx(np.sum((r[test] - X[test] @ dc) ** 2), rel=1e-9)
        expected = np.sqrt(sq / (len(r) / 3))
        assert fs.cv_rms(None if X is H else extra) == pytest.approx(expected, rel=1e-9)
    # the true effect (0.004 m RMS beside 0.01 m of noise) predicts held-out poses better
    assert fs.cv_rms(extra) < 0.97 * fs.cv_rms()


@pytest.mark.parametrize("seed", range(5))
def test_folded_holds_on_columns_one_fold_carries_and_on_singular_training_rows(seed):
    """Two edges of the Gram route, against lstsq: a column that lives (to 1e-10) on one fold only,
    whose training Gram a whole-less-fold subtraction would leave as rounding; and a candidate that
    is a combination of H's columns on the training rows (singular there), where lstsq gives the
    minimum-norm fit and a Cholesky that passes on rounding would not."""
    rng = np.random.default_rng(seed)
    P, k = 50, 5
    rows_pose, fold = np.repeat(np.arange(P), 3), folds(P, rng)
    f = fold[0]
    test = fold[rows_pose] == f
    H = rng.normal(size=(3 * P, k))
    H[:, -1] = np.where(test, rng.normal(size=3 * P), 1e-10 * rng.normal(size=3 * P))
    r = 1e-3 * rng.normal(size=3 * P)
    r -= H @ np.linalg.lstsq(H, r, rcond=None)[0]
    X = (H[:, :3] @ rng.normal(size=3))[:, None]
    X[test] = rng.normal(size=(test.sum(), 1))
    fs = Folded(H, r, rows_pose, fold)
    for extra in (None, X):
        A = H if extra is None else np.column_stack([H, extra])
        scale = np.linalg.norm(A[~test], axis=0)
        dc = np.linalg.lstsq(A[~test] / scale, r[~test], rcond=None)[0] / scale
        assert fs.held_out_sq(f, extra) == pytest.approx(np.sum((r[test] - A[test] @ dc) ** 2), rel=1e-6)


def test_screen_batches_many_candidates_and_breaks_exact_ties_in_candidate_order(system):
    """Hundreds of one-column candidates, a third restricted to one error (thousands of auxiliary
    signals are screened this way, a batch per size): every hit's drop is lstsq's; the true effect
    offered twice with the same values (an auxiliary torque and the model's own gravity torque) is
    found as the copy that comes first among the candidates, whichever that is."""
    rows_pose, H, J, Q, r, cands, _ = system
    rng = np.random.default_rng(5)
    noise = [Candidate("polynomial", (f"a{i}",), (f"a{i}",), rng.normal(size=(40, 1)), None if i % 3 else (1,))
             for i in range(300)]
    twin = Candidate("aux", ("tau",), ("s", "c", "t"), cands[1].values.copy())
    # the true effect again, offered to error 1 alone: were it offered to error 2 it would lead the hits
    elsewhere = Candidate("aux", ("tau1",), ("s1", "c1", "t1"), cands[1].values.copy(), (1,))
    base = basis(H, [np.linalg.qr(H, mode="r")])
    sigma2 = float(r @ r) / (len(r) - H.shape[1])
    for first, second in ((cands[1], twin), (twin, cands[1])):
        offered = [*noise, elsewhere, first, second, cands[0]]
        hits = screen(J, rows_pose, r, base, sigma2, offered, [0, 1, 2, 3])
        assert offered[hits[0].candidate] is first and hits[0].error == 2
        assert all(h.error == 1 for h in hits if offered[h.candidate].errors == (1,))  # offered to error 1 only
        for h in hits:
            X = _projected(Q, columns(J, offered[h.candidate], h.error, rows_pose))
            beta = np.linalg.lstsq(X, r, rcond=None)[0]
            assert h.drop == pytest.approx(float(np.sum((X @ beta) ** 2)), rel=1e-9)


def test_the_chi_square_tail_is_scipy_stats_to_the_last_bit():
    # chi2_logsf stands in for scipy.stats.chi2.logsf (an import of 0.4 s): the same numbers, so
    # diagnose's significance order and choices cannot move
    from scipy import stats

    from gecgen.loop.screening import chi2_logsf

    dof = np.arange(1, 61)[:, None]
    x = np.concatenate([[0.0, 1e-300, np.inf, np.nan], np.geomspace(1e-8, 1e4, 400)])[None, :] * np.ones_like(dof)
    dof = dof * np.ones_like(x)
    ours, theirs = chi2_logsf(x, dof), stats.chi2.logsf(x, dof)
    assert np.array_equal(ours, theirs, equal_nan=True)
    assert np.isnan(ours[:, 3]).all() and (ours[:, 0] == 0).all() and (ours[:, 2] == -np.inf).all()
    # near the median both branches are exercised: the switch sits where scipy's does
    median = stats.chi2.median(dof[:, 0])
    for d, m in zip(dof[:, 0], median):
        at = np.nextafter(m, [-np.inf, np.inf])
        assert np.array_equal(chi2_logsf(at, d), stats.chi2.logsf(at, d))


def test_the_noise_tests_tails_are_scipy_stats():
    # diagnose's noise p-value calls scipy.special's tails directly, as scipy.stats does for x > 0
    from scipy import special, stats

    ratio, dof, noise_dof = np.geomspace(0.05, 20, 200), np.arange(1, 201), 37
    assert np.array_equal(special.chdtrc(dof, ratio * dof), stats.chi2.sf(ratio * dof, dof))
    assert np.array_equal(special.fdtrc(dof, noise_dof, ratio), stats.f.sf(ratio, dof, noise_dof))



def test_one_column_candidates_as_least_squares_and_their_gram_shortcut_to_the_bit(system):
    """screen() takes a one-column candidate's 1 x 1 Gram matrix as its own eigenvalue and divides by
    it, where numpy's eigvalsh and solve would be called: the same numbers to the bit (so the screen's
    figures did not move), and the drops those of least squares on the explicit columns."""
    rng = np.random.default_rng(7)
    G, b = rng.uniform(1e-6, 10.0, (20000, 1, 1)), rng.normal(size=(20000, 1))
    assert np.array_equal(np.linalg.eigvalsh(G), G[:, :, 0])
    assert np.array_equal(np.linalg.solve(G, b[:, :, None])[:, :, 0], b / G[:, :, 0])
    rows_pose, H, J, Q, r, _, _ = system
    ones = [Candidate("polynomial", ("q1",), (f"t{k}",), rng.normal(size=(rows_pose.max() + 1, 1)))
            for k in range(6)]
    hits = screen(J, rows_pose, r, basis(H, [np.linalg.qr(H, mode="r")]), 1e-12, ones, [0, 1, 2, 3])
    assert len(hits) == 6 * 4  # every pair passes the pre-filter at this tiny variance
    for h in hits:
        X = _projected(Q, columns(J, ones[h.candidate], h.error, rows_pose))
        beta = np.linalg.lstsq(X, r, rcond=None)[0]
        assert h.drop == pytest.approx(float(np.sum((X @ beta) ** 2)), rel=1e-9)
        assert np.allclose(h.fitted, X @ beta, rtol=0, atol=1e-12)

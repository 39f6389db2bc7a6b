"""Banded LU with partial pivoting (LAPACK's dgbtf2 / dgbtrs, unblocked), compiled with numba.

The interior-point solver's KKT matrices (``ocp/ipm.py``) are banded with a half-bandwidth of a few
entries and tens of thousands of rows. LAPACK's routines through scipy do the same arithmetic but hand
their inner products to a threaded BLAS, whose threads cost more than the work at this size (and far
more on a busy machine: 28 ms instead of about 1 ms for 60,000 rows). These loops are called through
``locoplan.sim.native`` (compiled ahead of time where possible, numba's JIT otherwise).

Storage: ``ab`` of shape (n, 2 kl + ku + 1), column ``j`` of the matrix in row ``j`` of ``ab``, entry
(i, j) at ``ab[j, kl + ku + i - j]``; the first ``kl`` entries of each row are room for the fill-in.
"""

from __future__ import annotations

from numba import njit


@njit(cache=True)
def band_factor(ab, kl, ku, piv):
    """Factor ``ab`` in place (P A = L U); returns 0, or j + 1 where U(j, j) is exactly zero."""
    n = ab.shape[0]
    kv = kl + ku
    ju = 0
    info = 0
    for j in range(n):
        km = min(kl, n - 1 - j)
        jp = 0
        big = abs(ab[j, kv])
        for t in range(1, km + 1):
            a = abs(ab[j, kv + t])
            if a > big:
                big = a
                jp = t
        piv[j] = j + jp
        if ab[j, kv + jp] == 0.0:
            if info == 0:
                info = j + 1
            continue
        ju = max(ju, min(j + ku + jp, n - 1))
        if jp != 0:  # swap rows j and j + jp in columns j .. ju
            for c in range(j, ju + 1):
                r1 = kv + j - c
                r2 = kv + j + jp - c
                tmp = ab[c, r1]
                ab[c, r1] = ab[c, r2]
                ab[c, r2] = tmp
        d = ab[j, kv]
        for t in range(1, km + 1):
            ab[j, kv + t] /= d
        for c in range(j + 1, ju + 1):
            u = ab[c, kv + j - c]
            if u != 0.0:
                for t in range(1, km + 1):
                    ab[c, kv + j + t - c] -= ab[j, kv + t] * u
    return info


@njit(cache=True)
def band_solve(ab, kl, ku, piv, b):
    """Solve A x = b in place for each column of ``b`` (n, m) with the factors of :func:`band_factor` (every
    column in one sweep over the factors; each column's arithmetic is dgbtrs' own)."""
    n = ab.shape[0]
    kv = kl + ku
    m = b.shape[1]
    for j in range(n - 1):
        lm = min(kl, n - 1 - j)
        p = piv[j]
        for col in range(m):
            if p != j:
                tmp = b[p, col]
                b[p, col] = b[j, col]
                b[j, col] = tmp
            bj = b[j, col]
            if bj != 0.0:
                for t in range(1, lm + 1):
                    b[j + t, col] -= ab[j, kv + t] * bj
    for j in range(n - 1, -1, -1):
        i0 = max(0, j - kv)
        for col in range(m):
            b[j, col] /= ab[j, kv]
            bj = b[j, col]
            if bj != 0.0:
                for i in range(i0, j):
                    b[i, col] -= ab[j, kv + i - j] * bj


@njit(cache=True)
def band_assemble(full, bw, pos, hess, grad_g, sig, grad_e, pos_x, diag_x, pos_y, diag_y, fixed_pos):
    """Fill ``full`` (the storage of :func:`band_factor`, kl = ku = bw, zeroed here) with an interior-point
    method's KKT matrix for cells with p local variables at the unknowns ``pos[k, :p]`` and one equality
    whose multiplier is ``pos[k, p]``: per cell the block ``hess[k] + sum_j sig[k, j] grad_g[k, j] grad_g[k, j]'``
    with ``grad_e[k]`` as its border, plus the diagonals ``diag_x`` at ``pos_x`` and ``diag_y`` at ``pos_y``,
    and an identity row and column for each unknown in ``fixed_pos``."""
    kv = 2 * bw
    full[:, :] = 0.0
    n_cells, p = hess.shape[0], hess.shape[1]
    q = grad_g.shape[1]
    for k in range(n_cells):
        iy = pos[k, p]
        for a in range(p):
            i = pos[k, a]
            for b in range(p):
                j = pos[k, b]
                w = hess[k, a, b]
                for t in range(q):
                    w += sig[k, t] * grad_g[k, t, a] * grad_g[k, t, b]
                full[j, kv + i - j] += w
            full[iy, kv + i - iy] += grad_e[k, a]  # row i, column iy
            full[i, kv + iy - i] += grad_e[k, a]  # row iy, column i
    for t in range(pos_x.shape[0]):
        j = pos_x[t]
        full[j, kv] += diag_x[t]
    for t in range(pos_y.shape[0]):
        j = pos_y[t]
        full[j, kv] += diag_y[t]
    n = full.shape[0]
    for t in range(fixed_pos.shape[0]):
        f = fixed_pos[t]
        for d in range(-bw, bw + 1):
            j = f - d  # row f, column j
            if 0 <= j < n:
                full[j, kv + d] = 0.0
            i = f + d  # row i, column f
            if 0 <= i < n:
                full[f, kv + d] = 0.0
        full[f, kv] = 1.0

"""The adjugate and determinant of 4 x 4 matrices, for the numpy route and the compiled loops alike."""

from __future__ import annotations


def fill_adjugate(a, adj):
    """Fills ``adj`` with the adjugate of the 4 x 4 matrix ``a`` and returns its determinant.

    Expansion by complementary 2 x 2 minors, entry by entry: ``a[i, j]`` and ``adj[i, j]`` are
    numbers (one matrix, in a compiled loop of :mod:`._loops`) or (N,) arrays (N matrices stored
    entry-first, (4, 4, N), as :mod:`.jacobian` keeps them: far cheaper than a LAPACK call per
    matrix). One expression for both, so both routes round alike.
    """
    s0 = a[0, 0] * a[1, 1] - a[1, 0] * a[0, 1]
    s1 = a[0, 0] * a[1, 2] - a[1, 0] * a[0, 2]
    s2 = a[0, 0] * a[1, 3] - a[1, 0] * a[0, 3]
    s3 = a[0, 1] * a[1, 2] - a[1, 1] * a[0, 2]
    s4 = a[0, 1] * a[1, 3] - a[1, 1] * a[0, 3]
    s5 = a[0, 2] * a[1, 3] - a[1, 2] * a[0, 3]
    c5 = a[2, 2] * a[3, 3] - a[3, 2] * a[2, 3]
    c4 = a[2, 1] * a[3, 3] - a[3, 1] * a[2, 3]
    c3 = a[2, 1] * a[3, 2] - a[3, 1] * a[2, 2]
    c2 = a[2, 0] * a[3, 3] - a[3, 0] * a[2, 3]
    c1 = a[2, 0] * a[3, 2] - a[3, 0] * a[2, 2]
    c0 = a[2, 0] * a[3, 1] - a[3, 0] * a[2, 1]
    adj[0, 0] = a[1, 1] * c5 - a[1, 2] * c4 + a[1, 3] * c3
    adj[0, 1] = -a[0, 1] * c5 + a[0, 2] * c4 - a[0, 3] * c3
    adj[0, 2] = a[3, 1] * s5 - a[3, 2] * s4 + a[3, 3] * s3
    adj[0, 3] = -a[2, 1] * s5 + a[2, 2] * s4 - a[2, 3] * s3
    adj[1, 0] = -a[1, 0] * c5 + a[1, 2] * c2 - a[1, 3] * c1
    adj[1, 1] = a[0, 0] * c5 - a[0, 2] * c2 + a[0, 3] * c1
    adj[1, 2] = -a[3, 0] * s5 + a[3, 2] * s2 - a[3, 3] * s1
    adj[1, 3] = a[2, 0] * s5 - a[2, 2] * s2 + a[2, 3] * s1
    adj[2, 0] = a[1, 0] * c4 - a[1, 1] * c2 + a[1, 3] * c0
    adj[2, 1] = -a[0, 0] * c4 + a[0, 1] * c2 - a[0, 3] * c0
    adj[2, 2] = a[3, 0] * s4 - a[3, 1] * s2 + a[3, 3] * s0
    adj[2, 3] = -a[2, 0] * s4 + a[2, 1] * s2 - a[2, 3] * s0
    adj[3, 0] = -a[1, 0] * c3 + a[1, 1] * c1 - a[1, 2] * c0
    adj[3, 1] = a[0, 0] * c3 - a[0, 1] * c1 + a[0, 2] * c0
    adj[3, 2] = -a[3, 0] * s3 + a[3, 1] * s1 - a[3, 2] * s0
    adj[3, 3] = a[2, 0] * s3 - a[2, 1] * s1 + a[2, 2] * s0
    return s0 * c5 - s1 * c4 + s2 * c3 + s3 * c2 - s4 * c1 + s5 * c0

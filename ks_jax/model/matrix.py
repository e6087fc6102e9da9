"""The collision matrix K (docs/model.md, "The impulse exchange", step 2) and the world-frame
inverse inertias it is built from, in closed form (no LAPACK call per row)."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import linalg as la


def collision_matrix(mass1, inv_inertia1, r1, mass2, inv_inertia2, r2):
    """K = (1/m1 + 1/m2) Id - [r1]x I1^-1 [r1]x - [r2]x I2^-1 [r2]x, (3, 3), symmetric positive definite.

    mass_i: () kg; inv_inertia_i: (3, 3) the inverse inertia in the global frame, 1/(kg m^2);
    r_i: (3,) m, from vehicle i's CG to the impulse centroid. An impulse J on vehicle 1 (and -J on
    vehicle 2) changes the relative velocity at the centroid from u to u + K J."""
    eye = jnp.eye(3, dtype=r1.dtype)
    return ((1.0 / mass1 + 1.0 / mass2) * eye + la.from_rows(_arm(r1, inv_inertia1))
            + la.from_rows(_arm(r2, inv_inertia2)))


def _arm(r, a):
    """-[r]x A [r]x (rows of components) for r (3,) and A (3, 3), written with cross products: a
    product with the matrix [r]x would make XLA compute every x * 0 (and NaN * 0 is NaN)."""
    # the columns of B = [r]x A are r x (columns of A); the rows of B [r]x^T are r x (rows of B)
    r = la.vec(r)
    b_columns = [la.cross_c(r, column) for column in la.transpose_c(a)]
    return tuple(la.cross_c(r, row) for row in zip(*b_columns))


def inverse_inertia_world(inertia, trig):
    """(I^-1 in the global frame, R I_body^-1 R^T, (3, 3); and R, (3, 3)), from the body inertia
    ((3,) principal moments or a (3, 3) tensor, kg m^2) and ``trig`` = ``linalg.trig(yaw, pitch, roll)``.
    Closed form: the adjugate for a tensor, reciprocals for principal moments."""
    return _world_inverse(jnp.asarray(inertia), tuple(trig))


def _times_body(a, m):
    """a M (components): M as rows of components, or a (3,) array, the diagonal of M (each column of
    a scaled: XLA would compute every product by the zeros of a diagonal matrix, NaN * 0 being NaN)."""
    if isinstance(m, (tuple, list)):
        return la.matmul_c(a, m)
    d = la.vec(m)
    return tuple(tuple(row[j] * d[j] for j in range(3)) for row in la.mat(a))


def _body_inverse(inertia):
    """I_body^-1: rows of components from a (3, 3) inertia; from the principal moments (3,), the (3,)
    array of its diagonal (for ``_times_body``)."""
    if inertia.ndim == 1:
        return 1.0 / inertia
    det = la.det3(inertia)
    return tuple(tuple(c / det for c in row) for row in la.adjugate_c(inertia))


@jax.custom_jvp
def _world_inverse(inertia, trig):
    """(R M R^T, R) as (3, 3) arrays, M = I_body^-1, R from the six sines and cosines."""
    rot = la.rotation_c(*trig)
    world = la.matmul_c(_times_body(rot, _body_inverse(inertia)), rot, transpose_b=True)
    return la.from_rows(world), la.from_rows(rot)


@_world_inverse.defjvp
def _world_inverse_jvp(primals, tangents):
    """With W = R M (M = I_body^-1): d(R M R^T) = P + P^T - W dI W^T, P = dR W^T (dM = -M dI M; a
    diagonal inertia gives dI = diag(d)). Automatic differentiation of the forward gives the same
    derivative through the adjugate, the determinant and every intermediate 3x3 array, whose batched
    backward pass XLA assembles in concatenate loops that recompute shared products for each entry;
    here each entry of the tangent is a short sum of its own."""
    inertia, trig = primals
    d_inertia, d_trig = tangents
    rot, d_rot = jax.jvp(la.rotation_c, tuple(trig), tuple(d_trig))
    w = _times_body(rot, _body_inverse(inertia))
    world = la.matmul_c(w, rot, transpose_b=True)
    p = la.matmul_c(d_rot, w, transpose_b=True)
    q = la.matmul_c(_times_body(w, d_inertia if inertia.ndim == 1 else la.mat(d_inertia)), w, transpose_b=True)
    d_world = tuple(tuple(p[i][j] + p[j][i] - q[i][j] for j in range(3)) for i in range(3))
    return (la.from_rows(world), la.from_rows(rot)), (la.from_rows(d_world), la.from_rows(d_rot))

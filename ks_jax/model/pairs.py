"""The pairs of bodies that a watched motion looks at (docs/model.md, "Contact interactions"; ``model.interaction``
runs the motion): which pairs are watched, how far apart each pair is, and, where its footprints overlap, the
overlap's centroid and normal as automatic contact finds them and the pair's closing speed u_n there.

The bodies are given stacked: vehicles (``Vehicle`` of (N, ...) leaves, the V vehicles then the F fixed objects)
and their ``State`` (N, ...); a pair's geometry is worked about its CGs' midpoint, as automatic contact does, with a
pole's disc by ``contact.disc_contact``. The pairs against a box are worked together (``jax.vmap``), and those
against a pole together.

Cost: the close look at a pair (its separation, the overlap's centroid and normal) is taken only where the pair's
circles of reach meet and one of its vehicles moves, and for a batch (``jax.vmap``) only at the steps where some row
needs it (``any_row``).

Everything here is pure and unbatched, of static shapes (the pairs), and works under ``jax.jit``, ``jax.vmap`` and
differentiation.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from . import linalg as la
from .contact import contact_geometry, disc_gap, footprint, separation
from .contact.geometry import length_tolerance, reach, vertical_middle
from .contact.pole import disc_contact
from .packing import Packing


def pairs_of(vehicles: int, fixed: int, links=()):
    """The pairs watched (static): every pair of vehicles (i < j), then every vehicle with every fixed object; a
    pair coupled by a hitch (``links``: (towed, tow) pairs) is not watched: its footprints may overlap (a
    semi-trailer over its tow's fifth wheel)."""
    n = vehicles + fixed
    hitched = {tuple(sorted(link)) for link in links}
    return tuple((i, j) for i in range(vehicles) for j in range(i + 1, n) if (i, j) not in hitched)


def _centred(s1, s2):
    """The two states moved so that their CGs' midpoint (on the ground) is the origin, and that midpoint: the
    geometry is worked there, as automatic contact does, its tolerances grown with the midpoint's distance."""
    origin = (0.5 * (s1.position + s2.position)).at[2].set(0.0)
    return s1._replace(position=s1.position - origin), s2._replace(position=s2.position - origin), origin


def _pair_gap(v1, s1, v2, s2, pole):
    """() m: the separation of two bodies as they stand (< 0 overlapping); ``pole`` (static): body 2 is a pole's
    disc."""
    n1, n2, _ = _centred(s1, s2)
    return (disc_gap if pole else separation)(v1, n1, v2, n2, 0.0)


def _pair_contact(v1, s1, v2, s2, pole):
    """(separation () m, < 0 overlapping; centroid (3,) m; normal (3,), from body 2 into body 1) of two bodies as they
    stand, worked about their CGs' midpoint (as automatic contact does); ``pole`` (static): body 2 is a pole's
    disc."""
    n1, n2, origin = _centred(s1, s2)
    far = la.safe_norm(origin)
    gap = _pair_gap(v1, s1, v2, s2, pole)
    if pole:
        tol = length_tolerance(v1, v2, origin.dtype, far)
        xy, n, *_ = disc_contact(v1, n1, n2.position[:2], 0.5 * v2.width, footprint(v1, n1.position[:2], n1.yaw),
                                 tol, n1, n2.position[:2])
        point = jnp.stack([xy[0], xy[1], vertical_middle(v1, n1, v2, n2)])
        normal = jnp.stack([n[0], n[1], jnp.zeros_like(n[0])])
    else:
        geo = contact_geometry(v1, n1, v2, n2, far)
        point, normal = geo.point, geo.normal
    return gap, point + origin, normal


def material_velocity(point, s):
    """(3,) m/s: the velocity of the body's material point at ``point``."""
    return s.velocity + la.cross(s.angular_velocity, point - s.position)


def _closing(point, normal, s1, s2):
    """u_n: the relative velocity of body 1 over body 2 at ``point`` along ``normal``."""
    return la.mm(normal, material_velocity(point, s1) - material_velocity(point, s2))


def _by_kind(pairs, poles):
    """The pairs split by how their geometry is worked (static): (pole, their positions in ``pairs``, their first
    bodies, their second bodies), the pairs against a box, then those against a pole's disc; kinds with no pair left
    out."""
    for pole in (False, True):
        idx = [k for k, (_, j) in enumerate(pairs) if (j in poles) == pole]
        if idx:
            yield pole, idx, [pairs[k][0] for k in idx], [pairs[k][1] for k in idx]


def gaps(bodies, states, pairs, poles):
    """(P,) m: every pair's separation as the bodies stand."""
    gap = jnp.zeros(len(pairs), states.yaw.dtype)
    for pole, idx, i, j in _by_kind(pairs, poles):
        g = jax.vmap(lambda a, b, c, d: _pair_gap(a, b, c, d, pole))(
            _take(bodies.vehicle, i), _take(states, i), _take(bodies.vehicle, j), _take(states, j))
        gap = gap.at[jnp.asarray(idx)].set(g)
    return gap


@jax.custom_batching.custom_vmap
def any_row(flag):
    """``flag`` (() bool), which under ``jax.vmap`` becomes one unbatched flag: whether it holds in any row of the
    batch. A ``lax.cond`` on it stays a conditional under ``vmap`` (where a batched predicate would make both branches
    run for every row): the costly branch runs for the whole batch, and only when some row needs it. Its branches
    must then agree wherever the cheap one is taken by a row that would not need the costly one."""
    return flag


@any_row.def_vmap
def _any_row_batched(axis_size, in_batched, flag):
    return (jnp.any(flag) if in_batched[0] else flag), False


def _take(tree, idx):
    """The bodies ``idx`` (a static list) of a stacked tree, stacked in that order."""
    return jax.tree_util.tree_map(lambda x: jnp.stack([x[k] for k in idx]), tree)


def _circles_apart(v1, s1, v2, s2, moving, i, j):
    """For the pairs of bodies ``i`` and ``j`` (static lists; ``v1``, ``s1``, ``v2``, ``s2`` their vehicles and
    states, stacked in that order), how far apart their circles of reach are (``contact.geometry.reach``; < 0 where
    they meet) and whether one of their vehicles moves (``moving`` (V,))."""
    # a wall is a box kilometres long about a point of its face: its circle of reach holds any vehicle near it
    apart = la.safe_norm(s1.position[:, :2] - s2.position[:, :2]) - jax.vmap(reach)(v1) - jax.vmap(reach)(v2)
    moves = jnp.stack([moving[a] | (moving[b] if b < moving.shape[0] else False) for a, b in zip(i, j)])
    return apart, moves


def watch_gaps(bodies, states, moving, pairs, poles):
    """(P,) m: the gap of every pair as ``watch_pairs`` gives it, without the overlaps' centroids and normals: the
    separation (``gaps``) where the pair is watched, else the distance between its circles of reach."""
    gap = gaps(bodies, states, pairs, poles)
    for _, idx, i, j in _by_kind(pairs, poles):
        apart, moves = _circles_apart(_take(bodies.vehicle, i), _take(states, i), _take(bodies.vehicle, j),
                                      _take(states, j), moving, i, j)
        where = jnp.asarray(idx)
        gap = gap.at[where].set(jnp.where((apart < 0) & moves, gap[where], _stand_in_gap(apart)))
    return gap


def _stand_in_gap(apart):
    """The gap of a pair not looked at closely (apart, or at rest), which does not overlap as far as the watch is
    concerned: the distance between its circles of reach, 1 m where they meet."""
    return jnp.maximum(apart, 0.0) + jnp.where(apart < 0, 1.0, 0.0)


def watch_pairs(bodies, states, moving, pairs, poles, packed: bool = False):
    """(gap, point, normal, u_n) of every pair, (P,) (P, 3) (P, 3) (P,) (the pairs against a box vmapped together,
    those against a pole together), for bodies in ``states`` of which the vehicles ``moving`` (V,) bool move.

    A pair is looked at closely only where its circles of reach (``contact.geometry.reach``) meet and one of its
    vehicles moves: elsewhere it cannot overlap, or cannot approach, and its gap is the distance between the circles
    (> 0, a lower bound of the separation), its u_n 0. The close look (separation, and the overlap's centroid and
    normal by automatic contact's rules) runs for every pair, and for a whole batch, only at a step where some pair
    of some row needs it (``any_row``). ``packed`` (static): the pairs' values go to the close look's conditional
    packed, one flat array per dtype (``packing.Packing``), as an accelerator's path asks."""
    dtype = states.yaw.dtype
    gap, point, normal, un = (jnp.zeros(len(pairs), dtype), jnp.zeros((len(pairs), 3), dtype),
                              jnp.zeros((len(pairs), 3), dtype), jnp.zeros(len(pairs), dtype))
    for pole, idx, i, j in _by_kind(pairs, poles):
        v1, v2, s1, s2 = _take(bodies.vehicle, i), _take(bodies.vehicle, j), _take(states, i), _take(states, j)
        apart, moves = _circles_apart(v1, s1, v2, s2, moving, i, j)
        watched = (apart < 0) & moves
        far = _stand_in_gap(apart)

        packing = Packing((v1, s1, v2, s2), packed)

        def look(args, pole=pole, packing=packing):
            a, b, c, d = packing.unpack(args)
            g, pt, n = jax.vmap(lambda w, x, y, z: _pair_contact(w, x, y, z, pole))(a, b, c, d)
            return g, pt, n, jax.vmap(_closing)(pt, n, b, d)

        def glance(args, count=len(idx)):
            z = jnp.zeros((count, 3), dtype)
            return far, z, z, jnp.zeros(count, dtype)

        g, pt, n, u = jax.lax.cond(any_row(jnp.any(watched)), look, glance,
                                   packing.fenced(packing.pack((v1, s1, v2, s2))))
        where = jnp.asarray(idx)
        gap, point, normal = gap.at[where].set(jnp.where(watched, g, far)), point.at[where].set(pt), \
            normal.at[where].set(n)
        un = un.at[where].set(jnp.where(watched, u, 0.0))
    return gap, point, normal, un

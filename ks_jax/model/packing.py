"""A tree of arrays as one flat array per dtype, and back (``Packing``): how the watched motion carries its state,
and passes values to a conditional, on an accelerator's path (``model.interaction``, ``model.pairs``).

A conditional's operands and results are buffers of their own, and a loop's state is a buffer per leaf. A tree of
dozens of small leaves then costs dozens of copies, or of slices each made into an array of its own, where it enters
or leaves a conditional: on a GPU each is a transfer or a kernel of its own, and a step of a motion of one row is
bound by its launches. Packed, they are a few; a computation reads each leaf as a slice of the packed arrays. The
values are the same, to the rounding of a program fused otherwise: leaves of one dtype are put side by side and
taken back, nothing is converted. On a CPU a copy costs what it copies, and packing copies more: there the trees
are passed as they are (``packed`` False, the same program as without a ``Packing``).
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp


class Packing:
    """The leaves of trees shaped as ``template`` (its structure, shapes and dtypes) as one flat array per dtype, in
    the order of the dtypes' names, where ``packed``; else the trees as they are."""

    def __init__(self, template, packed: bool):
        leaves, self.treedef = jax.tree_util.tree_flatten(template)
        self.packed = packed
        self.dtypes = sorted({x.dtype.name for x in leaves})
        self.shapes = [(x.dtype.name, x.shape) for x in leaves]

    def pack(self, tree):
        if not self.packed:
            return tree
        leaves = jax.tree_util.tree_leaves(tree)
        return tuple(jnp.concatenate([jnp.ravel(x) for x in leaves if x.dtype.name == d]) for d in self.dtypes)

    def unpack(self, state):
        if not self.packed:
            return state
        flat, taken, out = dict(zip(self.dtypes, state)), dict.fromkeys(self.dtypes, 0), []
        for d, shape in self.shapes:
            size = math.prod(shape)
            out.append(flat[d][taken[d]:taken[d] + size].reshape(shape))
            taken[d] += size
        return jax.tree_util.tree_unflatten(self.treedef, out)

    def fenced(self, state):
        """``state`` (as ``pack`` gives it) behind an optimization barrier where packed, for a conditional's operand:
        XLA would otherwise take the packed arrays apart again before the conditional (its operands each a slice, a
        kernel each)."""
        return jax.lax.optimization_barrier(state) if self.packed else state

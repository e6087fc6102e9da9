"""Automatic contact (docs/model.md, "Automatic contact"): where and when two footprints meet under free
motion, the contact there, and the exchange at that contact.

Every function here is pure and unbatched (one pair of bodies), takes the model's pytrees in SI units
(``Vehicle``, ``State``, ``Contact`` of ``ks_jax.model.types``; vehicle 2 may be a fixed object,
``checks.is_fixed``) and works under ``jax.jit``, ``jax.vmap`` and ``jax.grad``. The states given are the
instant t = 0 from which the bodies move freely (``advance``): the case start, or any later instant a
caller starts a search from. Times are counted from it.

The interface, in the order a caller uses it:

- ``automatic_exchange(vehicle1, state1, vehicle2, state2, contact, normal_pitch, *, auto_point,
  auto_normal, smoothing=0.0, pole=False) -> ExchangeResult``: all of it in one call, the exchange at the
  automatic contact, as ``ks_jax.exchange`` gives it at an explicit one. ``contact.time`` is the first-contact
  time t_i; status ``NO_CONTACT`` (and no NaN) where the footprints do not touch within ``HORIZON`` s,
  ``INVALID_PARTED`` where they have parted again by t_i + penetration_time, and the input rules' status
  (NaN results) where an input breaks one. It is the two stages below, which a batched caller computes
  apart (``ks_jax.solve``):
- ``automatic_stage(vehicle1, state1, vehicle2, state2, contact, normal_pitch, status, *, auto_point,
  auto_normal, pole=False) -> AutoContact``: the contact of a row whose input rules gave ``status``
  (``checks.input_status``), on harmless stand-in inputs where that is not ``OK``; its ``geometry`` is None.
- ``exchange_at_contact(vehicle1, state1, vehicle2, state2, contact, status, auto, smoothing=0.0)
  -> ExchangeResult``: the exchange at ``auto`` (``automatic_stage`` of the same inputs and status).
- ``automatic_contact(vehicle1, state1, vehicle2, state2, contact, normal_pitch, *, auto_point,
  auto_normal, pole=False) -> AutoContact``: the contact with its overlap geometry (for pictures and
  checks), for inputs that keep the rules.

``AutoContact``: ``time`` () s (t_i, or ``HORIZON`` where none was found), ``found`` () bool, ``state1``,
``state2`` (the states at the exchange instant t_i + penetration_time), ``contact`` (the ``Contact`` used
there: point and normal automatic where ``auto_point``/``auto_normal``, else the given ones), ``geometry``
(``Contact2D``: the overlap, its centroid and normal at that instant), ``parted``, ``at_touch`` and
``touch_crush`` (see ``automatic.AutoContact``). ``normal_pitch`` () rad tilts the automatic normal up
(``tilt``); ``auto_point``/``auto_normal`` are static bools or traced bool arrays; ``pole`` (static bool)
reads vehicle 2's footprint as the disc of diameter ``vehicle2.width`` (``pole``).

The pieces, for callers that need one step alone:

- ``first_contact(vehicle1, state1, vehicle2, state2, gap=None) -> (t_i (), found () bool)``: the first
  time in [0, ``HORIZON``] at which the footprints touch (``search``); ``gap``: ``disc_gap`` for a pole.
- ``contact_geometry(vehicle1, state1, vehicle2, state2, coordinates=0.0, touched=None) -> Contact2D``:
  the overlap's centroid and normal of bodies as they stand (``overlap``).
- ``footprint(vehicle, xy, yaw) -> (4, 2)`` corners, ``advance(state, t) -> State`` (free motion),
  ``separation(vehicle1, state1, vehicle2, state2, t) -> ()`` m (> 0 apart, <= 0 touching) and ``disc_gap``
  (the same for a pole); ``overlap_polygon`` and ``polygon_area_centroid`` (the overlap of two footprints).

Modules: ``geometry`` (footprints, free motion, separation, tolerances, convex polygons: what the others
share), ``search`` (the first-contact search), ``overlap`` (the overlap's centroid and contact plane),
``pole`` (a disc instead of a box), ``automatic`` (the stage that puts them together, and the exchange).
Nothing here imports the layers above the model (``ks_jax.batch``, ``solve``, ``case``, ``sweeps``,
``cli``, ``plot``).
"""

from .automatic import AutoContact, automatic_contact, automatic_exchange, automatic_stage, exchange_at_contact
from .geometry import advance, footprint, polygon_area_centroid, separation
from .overlap import Contact2D, contact_geometry, overlap_polygon, tilt
from .pole import disc_gap
from .search import HORIZON, first_contact

__all__ = [
    "HORIZON",
    "AutoContact",
    "Contact2D",
    "advance",
    "automatic_contact",
    "automatic_exchange",
    "automatic_stage",
    "contact_geometry",
    "disc_gap",
    "exchange_at_contact",
    "first_contact",
    "footprint",
    "overlap_polygon",
    "polygon_area_centroid",
    "separation",
    "tilt",
]

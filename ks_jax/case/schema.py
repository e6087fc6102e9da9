"""What each field of a case file is: its kind of quantity (for units) and shape, and the kind of every
input and output path's number."""

from __future__ import annotations

VEHICLE_FIELDS = {  # key -> (kind, shape); shape None = scalar
    "mass": ("mass", None),
    "weight": ("force", None),
    "inertia": ("inertia", "inertia"),
    "length": ("length", None),
    "width": ("length", None),
    "height": ("length", None),
    "cg_to_front": ("length", None),
    "cg_height": ("length", None),
    "position": ("length", "vec23"),
    "yaw": ("angle", None),
    "pitch": ("angle", None),
    "roll": ("angle", None),
    "velocity": ("velocity", "vec23"),
    "speed": ("velocity", None),
    "course": ("angle", None),
    "yaw_rate": ("angular_velocity", None),
    "angular_velocity": ("angular_velocity", "vec3"),
    "wheelbase": ("length", None),
    "track": ("length", None),
    "cg_to_front_axle": ("length", None),
    "after": ("table", None),
    "hitch": ("table", None),
    "approach": ("list", None),
    "stiffness": ("table", None),
    "crush_profile": ("table", None),
}

STIFFNESS_FIELDS = {  # a vehicle's "stiffness": its damaged side's (docs/model.md, "Crush energy")
    "A": ("force_per_length", None),
    "B": ("force_per_area", None),
    "A_sigma": ("force_per_length", None),
    "B_sigma": ("force_per_area", None),
}

CRUSH_PROFILE_FIELDS = {  # a vehicle's "crush_profile": the measured crush across the damage
    "width": ("length", None),
    "depths": ("length", "list"),
    "pdof": ("angle", None),
    "side": ("text", None),
    "width_sigma": ("length", None),
    "depth_sigma": ("length", None),
}

HITCH_FIELDS = {  # a towed vehicle's "hitch" (docs/model.md, "Articulated vehicles: the case file")
    "to": ("index", None),
    "point": ("length", "vec2"),
    "point_on_tow": ("length", "vec2"),
    "max_angle": ("angle", None),
    "kind": ("text", None),
}

AFTER_FIELDS = {  # a vehicle's "after": how its wheels run from the exchange to rest
    "wheels": ("dimensionless", "wheels"),
    "steer": ("angle", None),
    "rolling_resistance": ("dimensionless", None),
}

APPROACH_FIELDS = {  # a phase of a vehicle's "approach" (docs/model.md, "The approach: the case file")
    **AFTER_FIELDS,
    "duration": ("time", None),
    "distance": ("length", None),
    "friction": ("dimensionless", None),
}

ROAD_FIELDS = {
    "friction": ("dimensionless", None),
    "time_step": ("time", None),
    "time_limit": ("time", None),
}

INTERACTION_FIELDS = {  # the exchanges after the first (docs/model.md, "Contact interactions")
    "restitution": ("dimensionless", None),
    "friction": ("dimensionless", None),
    "penetration_time": ("time", None),
    "approach_tolerance": ("velocity", None),
    "max_exchanges": ("count", None),
}

CONTACT_FIELDS = {
    "point": ("length", "vec3"),
    "normal": ("angle", "normal"),
    "normal_pitch": ("angle", None),
    "restitution": ("dimensionless", None),
    "friction": ("dimensionless", None),
    "penetration_time": ("time", None),
}

TEXT_FIELDS = {"name", "description", "notes", "source", "...", "make", "model"}

CASE_FIELDS = {"name", "description", "notes", "source", "vehicles", "fixed", "between", "contact", "road",
               "interaction", "pairs", "unknowns", "evidence", "options", "reference"}

INPUT_KINDS = {
    "mass": "mass", "inertia": "inertia", "length": "length", "width": "length", "height": "length",
    "cg_to_front": "length", "cg_height": "length", "position": "length", "yaw": "angle", "pitch": "angle",
    "roll": "angle", "speed": "velocity", "course": "angle", "velocity_z": "velocity",
    "angular_velocity": "angular_velocity", "yaw_rate": "angular_velocity",
    "point": "length", "normal": "angle", "normal_pitch": "angle", "restitution": "dimensionless",
    "friction": "dimensionless", "penetration_time": "time",
    "wheelbase": "length", "track": "length", "cg_to_front_axle": "length", "brake": "dimensionless",
    "steer": "angle", "rolling_resistance": "dimensionless",
}

OUTPUT_KINDS = {
    "point": "length", "normal": "dimensionless", "time": "time", "impulse": "impulse",
    "impulse_magnitude": "impulse", "impulse_normal": "impulse", "impulse_tangential": "impulse",
    "impulse_azimuth": "degrees", "impulse_elevation": "degrees", "sliding": "dimensionless",
    "closing_velocity": "velocity", "separation_velocity": "velocity", "energy_loss": "energy",
    "delta_v": "velocity", "delta_v_magnitude": "velocity", "delta_v_body": "velocity",
    "delta_yaw_rate": "angular_velocity", "velocity_after": "velocity", "speed_after": "velocity",
    "course_after": "degrees", "angular_velocity_after": "angular_velocity",
    "yaw_rate_after": "angular_velocity", "pdof": "degrees", "pdof_clock": "dimensionless",
    "crush": "length", "ees": "velocity",
    "delta_v_cumulative": "velocity", "delta_v_cumulative_magnitude": "velocity", "delta_v_cumulative_pdof": "degrees",
    "energy_loss_total": "energy",
    "rest_position": "length", "rest_yaw": "degrees", "rotation_to_rest": "degrees", "time_to_rest": "time",
    "distance_to_rest": "length", "at_rest": "dimensionless",
    # at the start of an approach phase (``paths.parse_path`` names them "approach.<field>")
    "approach.speed": "velocity", "approach.time": "time", "approach.position": "length", "approach.yaw": "degrees",
    "approach.distance": "length",
    # a vehicle's state at a time (``paths.parse_path`` names them "at.<field>")
    "at.speed": "velocity", "at.position": "length", "at.velocity": "velocity", "at.yaw": "degrees",
    "at.yaw_rate": "angular_velocity", "at.distance": "length",
}

"""Quantities with units in case files, converted once to SI with pint.

A case writes ``"30 um"``, ``"0.5 kPa"``, ``"39.5 deg"``; the model stores plain floats in SI
(m, Pa, rad, s, kg, N). Bare numbers are refused for dimensional quantities (a missing unit is a
common, silent error), except ``0``, which is zero in every unit.
"""
from __future__ import annotations

import functools
import sys
from typing import Annotated

from pydantic import BeforeValidator, PlainSerializer


@functools.lru_cache(maxsize=1)
def registry():
    """pint's unit registry, made on first use. Import cost (validate within 2 s, #16): pint's
    optional dask support is not loaded (orchestrator has no dask quantities; ~0.2 s), and the
    parsed unit definitions come from pint's own cache (``cache_folder=":auto:"``; ~0.3 s), or are
    parsed afresh when it cannot be used."""
    block = "dask" not in sys.modules
    if block:
        sys.modules["dask"] = None                 # pint.compat: `import dask` -> ImportError
    try:
        import pint
    finally:
        if block:
            sys.modules.pop("dask", None)
    try:
        return pint.UnitRegistry(cache_folder=":auto:")
    except Exception:                              # noqa: BLE001 - an unwritable cache: parse afresh
        return pint.UnitRegistry()


def __getattr__(name):
    if name == "ureg":
        return registry()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

#: pint dimensionality and the SI unit each quantity kind is stored in.
KINDS = {
    "length": ("[length]", "m", "30 um"),
    "pressure": ("[pressure]", "Pa", "0.5 kPa"),
    "density": ("[mass] / [length] ** 3", "kg/m^3", "2500 kg/m^3"),
    "time": ("[time]", "s", "1 ms"),
    "angle": ("", "rad", "39.5 deg"),
    "angular_velocity": ("1 / [time]", "rad/s", "0.1 deg/s"),
    "velocity": ("[length] / [time]", "m/s", "0.2 m/s"),
    "force": ("[force]", "N", "1 uN"),
    "mass": ("[mass]", "kg", "1 mg"),
    "energy": ("[energy]", "J", "1 nJ"),
    "torque": ("[force] * [length]", "N*m", "1 uN*m"),
    "frequency": ("1 / [time]", "1/s", "1/s"),
    "acceleration": ("[length] / [time] ** 2", "m/s^2", "9.81 m/s^2"),
    "surface_energy": ("[energy] / [length] ** 2", "J/m^2", "0.05 J/m^2"),
    "strain_rate": ("1 / [time]", "1/s", "0.001 1/s"),
}


class UnitError(ValueError):
    """Raised (inside pydantic validation) for a bad or missing unit."""


def to_si(value, kind: str) -> float:
    """Convert ``value`` (a string with unit, or 0) of quantity ``kind`` to a float in SI units."""
    dim, si, example = KINDS[kind]
    if isinstance(value, bool):
        raise UnitError(f"expected a {kind} with a unit such as '{example}', got {value!r}")
    if isinstance(value, (int, float)):
        if value == 0:
            return 0.0
        if kind == "angle":
            raise UnitError(f"angle {value!r} has no unit; write e.g. '{value} deg' or '{value} rad'")
        raise UnitError(f"{value!r} has no unit; write it with one, e.g. '{value} {si}' (like '{example}')")
    if not isinstance(value, str):
        raise UnitError(f"expected a {kind} string with a unit such as '{example}', got {type(value).__name__}")
    ureg = registry()
    pint = sys.modules["pint"]
    try:
        q = ureg.Quantity(value.strip())
    except Exception as exc:  # pint raises several kinds
        raise UnitError(f"cannot read {value!r} as a {kind} ({exc}); write e.g. '{example}'") from None
    if not isinstance(q, pint.Quantity):
        q = ureg.Quantity(q)
    if kind == "angle":
        if q.dimensionless:
            if q.units == ureg.dimensionless:
                raise UnitError(f"angle {value!r} has no unit; write e.g. '{q.magnitude} deg'")
            return float(q.to("rad").magnitude)
        raise UnitError(f"{value!r} is not an angle; write e.g. '{example}'")
    if kind == "angular_velocity":
        try:
            return float(q.to("rad/s").magnitude)
        except pint.DimensionalityError:
            raise UnitError(f"{value!r} is not an angular velocity; write e.g. '{example}'") from None
    if q.dimensionless and q.units == ureg.dimensionless:
        raise UnitError(f"{value!r} has no unit; write it with one, e.g. '{example}'")
    try:
        return float(q.to(si).magnitude)
    except pint.DimensionalityError:
        raise UnitError(f"{value!r} has units of {q.dimensionality}, not a {kind}; write e.g. '{example}'") from None


def _validator(kind: str):
    def v(value):
        if isinstance(value, float) and getattr(v, "_already_si", False):
            return value
        return to_si(value, kind)
    return v


def Q(kind: str):
    """Annotated float type for a quantity of ``kind`` given with units, stored in SI."""
    _, si, _ = KINDS[kind]
    return Annotated[float, BeforeValidator(_validator(kind)),
                     PlainSerializer(lambda x: f"{x!r} {si}" if x != 0 else 0, when_used="json")]


Length = Q("length")
Pressure = Q("pressure")
Density = Q("density")
Time = Q("time")
Angle = Q("angle")
AngularVelocity = Q("angular_velocity")
Velocity = Q("velocity")
Force = Q("force")
Torque = Q("torque")
SurfaceEnergy = Q("surface_energy")
Acceleration = Q("acceleration")
StrainRate = Q("strain_rate")

"""What the measurements determine: the singular directions of the scaled identification
Jacobian, the posterior standard deviation along each (measurements plus the prior toward the
machine file), and the directions they leave open, said in the shop's words.

Directions are in scaled variables ``(p - p_file) / SCALE``; a combination is reported in the
interface units (mm, degrees), largest component +1, so its sign is the same on every run.
Pure: no I/O.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .model import PARAMETERS, SCALE, WORDS, to_interface, unit

#: A direction whose singular value is below this fraction of the largest is one the tool tips
#: cannot see at all (an exact dependency: the common slider zero against da).
RANK_RTOL = 1e-9

#: A direction whose posterior standard deviation exceeds this many typical errors
#: (:data:`~.model.SCALE`) is decided mostly by the prior, not by the measurements: reported.
WEAK_STD = 0.5

#: Components below this fraction of the largest are left out of a combination.
SHOWN = 0.1


@dataclass(frozen=True)
class Direction:
    """One singular direction: relative singular value, posterior std along it (typical
    errors; NaN when the noise is unknown), and its combination (name -> component, interface
    units, largest +1)."""

    relative: float
    std: float
    combination: dict[str, float]

    @property
    def null(self) -> bool:
        return self.relative < RANK_RTOL

    @property
    def weak(self) -> bool:
        return self.null or bool(self.std > WEAK_STD)


def directions(jac: np.ndarray, free: list[int], sigma: float | None) -> list[Direction]:
    """The singular directions of ``jac`` (rows, P) in scaled variables over the parameters
    ``free`` (indices into :data:`PARAMETERS`), strongest first. With the noise ``sigma`` (mm)
    each gets its posterior std: sigma / sqrt(s^2 + sigma^2) typical errors (the prior has 1)."""
    _, s, vt = np.linalg.svd(jac, full_matrices=False)
    s = np.r_[s, np.zeros(len(free) - len(s))]
    if vt.shape[0] < len(free):  # fewer rows than parameters: complete the basis
        vt = np.linalg.svd(np.vstack([jac, np.zeros((len(free) - jac.shape[0], len(free)))]))[2]
    relative = s / s[0] if s[0] > 0 else np.zeros_like(s)
    std = np.full(len(s), np.nan) if sigma is None else sigma / np.sqrt(s**2 + sigma**2)
    return [Direction(float(relative[k]), float(std[k]), combination(vt[k], free)) for k in range(len(s))]


def combination(vector: np.ndarray, free: list[int]) -> dict[str, float]:
    """A scaled direction as name -> component in interface units, largest +1 (sign fixed)."""
    physical = np.array([to_interface(PARAMETERS[k], float(v * SCALE[k])) for v, k in zip(vector, free, strict=True)])
    lead = int(np.argmax(np.abs(physical)))
    physical = physical / physical[lead]
    order = np.argsort(-np.round(np.abs(physical), 2), kind="stable")  # ties in the order of PARAMETERS
    return {PARAMETERS[free[j]]: round(float(physical[j]), 3) for j in order if abs(physical[j]) >= SHOWN}


def _listed(names: list[str]) -> str:
    words = [WORDS[n] for n in names]
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]


def _change(combination: dict[str, float]) -> str:
    return ", ".join(f"{v:+.2f} {unit(n)} {n}" for n, v in combination.items())


def explain(direction: Direction) -> str:
    """One sentence a shop can act on for a direction the measurements leave open."""
    names = list(direction.combination)
    values = np.array(list(direction.combination.values()))
    together = ("changing them all by the same amount" if np.allclose(values, values[0], rtol=0.02)
                else f"changing them together as {_change(direction.combination)}")
    if direction.null:
        return (f"{_listed(names)} cannot be told apart by tool tips: {together} moves no tip. Along that change "
                "all keep the file's values and what the tips do see is fitted; to set them, measure one another way "
                "and give it with --fix")
    lead = names[0]
    std = to_interface(lead, direction.std * SCALE[PARAMETERS.index(lead)])
    return (f"{_listed(names)} are told apart only to +-{std:.3g} {unit(lead)} of {lead} ({together} moves the tips "
            "by less than the noise over these poses): the fit keeps near the file's values there; more poses from "
            "'verne-post calibrate --plan N MEASURED.csv -o more.csv' separate them")


__all__ = ["RANK_RTOL", "WEAK_STD", "Direction", "combination", "directions", "explain"]

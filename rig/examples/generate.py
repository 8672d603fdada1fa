"""Make the bundled example runs from our own quasi-static loop model.

``python -m rig.examples.generate [OUT_DIR]`` rewrites ``rig/examples/runs``. The runs are
made from the reference nominal model (run-format.md) of the seed 000 pairs plus Coulomb
friction, a runout term over the eccentric-shaft angle, sensor noise and 23-bit encoder
quantisation, on the GB/T step-and-dwell torque sequence (0 -> +T -> 0 -> -T -> 0, the unit
preloaded to -T before t = 0). They are demonstration data, not measurements; the true values
used to make them are stored in each run.json under ``generator`` so tests can check the
analysis against them.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path
from typing import Any

import numpy as np

from analysis.models.by_kind import nominal_model_for_unit
from analysis.models.seed000_unit import InternalPairUnit
from rig.examples import RUNS_DIR, UNITS_DIR
from rig.runformat import Campaign, Run, write_campaign, write_run

COUNTS_PER_REV = 2**23
SAMPLE_RATE_HZ = 100.0


def load_unit(name: str) -> dict[str, Any]:
    """A bundled unit (``rig/examples/units/<name>.json``, seed 000 Tables 2 and 3)."""
    return json.loads((UNITS_DIR / f"{name}.json").read_text())


def gbt_step_profile(
    rated_torque_Nm: float, steps: int = 10, dwell_s: float = 0.5, ramp_s: float = 0.2
) -> tuple[np.ndarray, np.ndarray]:
    """Commanded torque (N*m) against time (s): 0 -> +T -> 0 -> -T -> 0 in equal steps.

    Each step ramps linearly for ``ramp_s`` then dwells for ``dwell_s``; sampled at
    SAMPLE_RATE_HZ. Returns (t_s, torque_Nm).
    """
    levels = (
        np.concatenate(
            [
                np.linspace(0, 1, steps + 1),
                np.linspace(1, 0, steps + 1)[1:],
                np.linspace(0, -1, steps + 1)[1:],
                np.linspace(-1, 0, steps + 1)[1:],
            ]
        )
        * rated_torque_Nm
    )
    knots_t = [0.0]
    knots_T = [levels[0]]
    t = dwell_s
    knots_t.append(t)
    knots_T.append(levels[0])
    for level in levels[1:]:
        t += ramp_s
        knots_t.append(t)
        knots_T.append(level)
        t += dwell_s
        knots_t.append(t)
        knots_T.append(level)
    t_s = np.arange(0.0, knots_t[-1], 1.0 / SAMPLE_RATE_HZ)
    return t_s, np.interp(t_s, knots_t, knots_T)


def make_run(
    run_id: str,
    unit: dict[str, Any],
    *,
    input_angle_deg: float,
    rated_torque_Nm: float = 10.0,
    friction_Nm: float = 0.15,
    runout_phase_deg: float = 30.0,
    twist_noise_arcsec: float = 0.5,
    torque_noise_Nm: float = 0.004,
    seed: int = 0,
) -> Run:
    """One run of the example loop model (see the module docstring); any unit kind of
    :mod:`analysis.models.by_kind`, the runout term for the seed 000 pair only."""
    rng = np.random.default_rng(seed)
    model, _ = nominal_model_for_unit(unit, rated_torque_Nm)
    runout_arcmin = 0.0
    if unit.get("kind", "internal_involute") == "internal_involute":
        parsed, _ = InternalPairUnit.from_mapping(unit)
        alpha = math.radians(parsed.pressure_angle_deg)
        runout_mm = ((parsed.runout_internal_mm or 0.0) + (parsed.runout_external_mm or 0.0)) / 2
        # seed 000 eqs. (3) and (7): the center distance error of the runout, once per turn
        runout_um = 2.0 * math.tan(alpha) * 1000.0 * runout_mm / 2.0
        runout_arcmin = 6.876 * runout_um / (parsed.module_mm * parsed.z_internal)
    play_arcmin = model.play_arcmin + runout_arcmin * math.cos(
        math.radians(input_angle_deg - runout_phase_deg)
    )
    t_s, command = gbt_step_profile(rated_torque_Nm)
    # Coulomb friction: the gear flanks carry the sensed torque minus the friction, which
    # opposes the direction of torque change (branches separate by 2 T_f / K in twist).
    direction = np.sign(np.gradient(command))
    direction = np.where(direction == 0, np.nan, direction)
    direction = _fill_forward(direction, start=1.0)
    flank_torque = command - direction * friction_Nm
    flank = np.sign(flank_torque)
    flank = _fill_forward(np.where(flank == 0, np.nan, flank), start=-1.0)
    twist = flank * play_arcmin / 2.0 + flank_torque / model.stiffness_Nm_per_arcmin
    twist = twist + rng.normal(0.0, twist_noise_arcsec / 60.0, t_s.size)
    offset_deg = 123.456 + input_angle_deg / -8.0
    counts = np.round((offset_deg + twist / 60.0) / 360.0 * COUNTS_PER_REV)
    output_angle_deg = counts * 360.0 / COUNTS_PER_REV
    torque = command + rng.normal(0.0, torque_noise_Nm, t_s.size)
    temperature = 21.0 + 0.002 * t_s + rng.normal(0.0, 0.01, t_s.size)
    return Run.from_arrays(
        run_id,
        t_s,
        torque,
        output_angle_deg,
        input_angle_deg=np.full(t_s.size, input_angle_deg),
        temperature_C=np.round(temperature, 3),
        unit=unit,
        test={
            "rated_torque_Nm": rated_torque_Nm,
            "input_angle_deg": input_angle_deg,
            "temperature_C": 21.0,
            "cycles": 1,
            "plan": "gbt-steps",
            "dwell_s": 0.5,
            "ramp_s": 0.2,
            "steps_per_quarter": 10,
        },
        sensors={"encoder_counts_per_rev": COUNTS_PER_REV, "torque_full_scale_Nm": 20.0},
        extra_meta={
            "generator": {
                "what": "rig.examples.generate: reference nominal model + Coulomb friction + "
                "runout + noise (demonstration data, not a measurement)",
                "true_play_arcmin": play_arcmin,
                "true_lost_motion_arcmin": play_arcmin
                + 2.0 * 0.03 * rated_torque_Nm / model.stiffness_Nm_per_arcmin,
                "true_backlash_arcmin": play_arcmin
                + 2.0 * friction_Nm / model.stiffness_Nm_per_arcmin,
                "true_stiffness_Nm_per_arcmin": model.stiffness_Nm_per_arcmin,
                "true_friction_Nm": friction_Nm,
                "twist_noise_arcsec": twist_noise_arcsec,
                "seed": seed,
            }
        },
    )


def _fill_forward(values: np.ndarray, start: float) -> np.ndarray:
    """Replace NaN by the last finite value before it (``start`` before the first)."""
    index = np.where(np.isfinite(values), np.arange(values.size), -1)
    index = np.maximum.accumulate(index)
    return np.where(index >= 0, values[np.maximum(index, 0)], start)


def generate(out_dir: Path = RUNS_DIR) -> list[Path]:
    """Write the example runs and the example campaign; returns the folders written."""
    pair1 = load_unit("seed000-pair1")
    pair3 = load_unit("seed000-pair3")  # pair 1 at the eq. (9) eccentric distance (standard)
    written = [
        write_run(
            make_run("pair1-pos000", pair1, input_angle_deg=0.0, seed=1), out_dir / "pair1-pos000"
        ),
        write_run(
            make_run("pair3-pos000", pair3, input_angle_deg=0.0, seed=2), out_dir / "pair3-pos000"
        ),
    ]
    runs = [
        make_run(f"pair1-pos{angle:03d}", pair1, input_angle_deg=float(angle), seed=10 + i)
        for i, angle in enumerate((0, 90, 180, 270))
    ]
    campaign = Campaign(
        meta={
            "format": "rig-campaign/1",
            "name": "pair1-positions",
            "runs": [run.run_id for run in runs],
        },
        runs=runs,
    )
    written.append(write_campaign(campaign, out_dir / "campaign-pair1-positions"))
    return written


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else RUNS_DIR
    for folder in generate(target):
        print(folder)

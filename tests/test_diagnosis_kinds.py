"""The diagnosis works for every unit kind with a nominal model (seed 002 cycloid, seed 001
beveloid), not only the seed 000 pair."""

from __future__ import annotations

import json

from rig.diagnose import diagnose_campaign
from rig.examples import UNITS_DIR
from rig.examples.generate import make_run
from rig.runformat import Campaign

CYCLOID = json.loads((UNITS_DIR / "cycloid-seed002.json").read_text())
BEVELOID = json.loads((UNITS_DIR / "beveloid-seed001.json").read_text())


def _campaign(friction_Nm: float, unit: dict = CYCLOID, rated_Nm: float = 200.0) -> Campaign:
    runs = [
        make_run(f"unit-pos{angle:03d}", unit, input_angle_deg=float(angle),
                 rated_torque_Nm=rated_Nm, friction_Nm=friction_Nm, twist_noise_arcsec=0.3,
                 torque_noise_Nm=rated_Nm / 1e4, seed=40 + i)
        for i, angle in enumerate((0, 90, 180, 270))
    ]
    return Campaign(meta={"format": "rig-campaign/1", "name": "cycloid",
                          "runs": [r.run_id for r in runs]}, runs=runs)


def test_cycloid_campaign_without_effect_is_none_and_with_friction_is_friction() -> None:
    clean = diagnose_campaign(_campaign(0.0)).to_dict()
    assert clean["verdict"] == "none", clean["verdict"]
    rubbing = diagnose_campaign(_campaign(8.0)).to_dict()  # 4 % of 200 N·m
    assert rubbing["verdict"] == "friction", (rubbing["verdict"], rubbing.get("candidates"))
    best = rubbing["ranking"][0]
    assert best["effect"] == "friction" and best["shrink"] > 0.7
    assert abs(best["params"]["friction_Nm"] - 8.0) < 1.0


def test_beveloid_campaign_with_friction_is_friction() -> None:
    assert diagnose_campaign(_campaign(0.0, BEVELOID, 20.0)).to_dict()["verdict"] == "none"
    rubbing = diagnose_campaign(_campaign(0.8, BEVELOID, 20.0)).to_dict()
    assert rubbing["verdict"] == "friction" and rubbing["ranking"][0]["shrink"] > 0.7

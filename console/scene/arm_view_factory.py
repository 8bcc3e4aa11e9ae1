"""Which drawing an arm gets, apart from the drawings: the soft arm's or the extensible arm's.

Kept out of :mod:`console.scene.arm_view` because both drawings subclass its
:class:`~console.scene.arm_view.ArmView`: the base knows neither arm, this module knows both.
"""

from __future__ import annotations

import viser

from console.core.model import ArmModel, ExtensibleModel, SoftArmModel
from console.scene.arm_view import ArmView, Method
from console.scene.dead_band import DeadBand
from console.scene.extensible_arm_view import ExtensibleArmView
from console.scene.soft_arm_view import SoftArmView


def make_arm_view(scene: viser.SceneApi, model: ArmModel, root: str = "/arm",
                  method: Method = "skinned",
                  dead_band: DeadBand | None = DeadBand()) -> ArmView[ArmModel]:
    """The view class matching the model's robot kind."""
    if isinstance(model, SoftArmModel):
        return SoftArmView(scene, model, root, method, dead_band)
    if isinstance(model, ExtensibleModel):
        return ExtensibleArmView(scene, model, root, method, dead_band)
    raise TypeError(f"no arm view for {type(model).__name__}")

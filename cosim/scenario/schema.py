"""The scene file schema as markdown (``drillcosim schema``, ``docs/scenes.md``): the plant's
tables (:func:`plant.scene.schema_markdown`), then those of the co-simulation
(:func:`cosim_schema_markdown`: ``[plant]``, ``[controller]``, ``[top_drive_controller]``,
``[cosim]``), and how overrides name keys."""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from drillcosim.controller import ControllerParams, TopDriveControllerParams
from drillcosim.plant.scene import schema_markdown

from .config import COSIM_KEYS

__all__ = ["cosim_schema_markdown", "scene_schema"]


def scene_schema() -> str:
    """The whole scene schema (plant tables, then the co-simulation's) as markdown."""
    return schema_markdown() + "\n" + cosim_schema_markdown()


def _default_text(name: str, d: Any) -> str:
    """A default value as the schema tables show it."""
    if name == "gain_matrix":
        return str(d)
    return ("inf" if isinstance(d, float) and math.isinf(d) else
            str(d).lower() if isinstance(d, bool) else f'"{d}"' if isinstance(d, str)
            else f"{d:g}")


def cosim_schema_markdown() -> str:
    """The ``[plant]``, ``[controller]``, ``[top_drive_controller]`` and ``[cosim]`` tables as
    markdown (for ``docs/scenes.md``).

    """
    lines = ["## [plant]", "",
             "Which plant FMU runs the scene (`cosim.scenario.config`).", "",
             "| key | default | unit | meaning |", "|---|---|---|---|",
             "| fmu | - | - | path of a plant FMU (any maker; relative to the scene file's "
             "folder) instead of the built DrillstringPlant.fmu; `drillcosim run --plant-fmu` "
             "overrides it |", "",
             "## [controller]", "",
             "Strain P-feedback controller (`controller.ControllerParams`; passed to "
             "StrainController.fmu).", "",
             "| key | default | unit | meaning |", "|---|---|---|---|"]
    ctrl_units = {"gain": "N", "mode": "-", "force_limit": "N", "symmetric_force_limit": "N",
                  "switch_on_time": "s", "lag_time_constant": "s", "enabled": "-",
                  "gain_matrix": "1"}
    ctrl_text = {
        "gain": "force per unit strain, >= 0 (paper: 1e9)",
        "mode": "'unrestricted' (push and pull) or 'compressive_only' (push only)",
        "force_limit": "peak push force in compressive_only mode",
        "symmetric_force_limit": "limit on abs(force) in unrestricted mode (inf = none)",
        "switch_on_time": "controller output is zero before this time",
        "lag_time_constant": "first-order actuator lag; 0 = none",
        "enabled": "false = open loop (the plant runs alone)",
        "gain_matrix": "relative gains M (n_sites x n_sites, row i = force of site i from the "
                       "strain of site j), the same for both axes: F_axis = gain * M @ "
                       "strain_axis (MIMO across the sites); [] or the identity = one P law "
                       "per channel. A scene with another number of sites than 2 or a matrix "
                       "runs StrainController_<scene>.fmu (`drillcosim build --scene`)",
        "fmu": "path of a controller FMU (any maker; relative to the scene file's folder) "
               "instead of the built StrainController.fmu; `drillcosim run --controller-fmu` "
               "overrides it",
    }
    defaults: dict[str, Any] = {f.name: f.default for f in fields(ControllerParams)}
    defaults["enabled"] = False
    defaults["gain_matrix"] = "[]"
    ctrl_units["fmu"] = "-"
    for name in ctrl_units:
        if name == "fmu":
            lines.append(f"| fmu | - | - | {ctrl_text['fmu']} |")
            continue
        lines.append(f"| {name} | {_default_text(name, defaults[name])} | {ctrl_units[name]} | "
                     f"{ctrl_text[name]} |")
    lines += ["", "The plant and controller FMUs connect by name; before the first step the pair "
              "is checked (causality, type, unit, nothing connected twice, start values), "
              "every problem in one line naming both FMUs and the variable (exit code 2). "
              "Plant inputs of sites the controller does not serve keep their start value, "
              "with a warning naming them ([interop.md](interop.md)).", "",
              "## [top_drive_controller]", "",
              "Top-drive speed controller (`controller.TopDriveControllerParams`; passed to "
              "TopDriveController.fmu): motor torque T_m = p_gain e + i_gain integral(e) + "
              "torque_feedback top_torque, e = speed reference - top_rotary_speed. Needs "
              "`[top_drive] mode = \"torque\"` (docs/physics.md section 6).", "",
              "| key | default | unit | meaning |", "|---|---|---|---|"]
    td_text = {"target_speed": ("rad/s", "target rotary speed of the drive, abs <= 1e3"),
               "p_gain": ("N m s/rad", "proportional gain P, >= 0"),
               "i_gain": ("N m/rad", "integral gain I, >= 0"),
               "torque_feedback": ("1", "top-torque feedback gain k_T, -10 <= k_T < 1 "
                                        "(0 = plain PI)"),
               "ramp_time": ("s", "the speed reference ramps from 0 over this time, >= 0"),
               "enabled": ("-", "false = no top-drive controller"),
               "fmu": ("-", "path of a top-drive controller FMU (any maker) instead of the "
                            "built TopDriveController.fmu")}
    td_defaults: dict[str, Any] = {f.name: f.default for f in fields(TopDriveControllerParams)}
    td_defaults["enabled"] = False
    for name, (unit, text) in td_text.items():
        ds = "-" if name == "fmu" else _default_text(name, td_defaults[name])
        lines.append(f"| {name} | {ds} | {unit} | {text} |")
    lines += ["", "## [cosim]", "",
              "Co-simulation settings (`cosim.scenario.config.CosimSettings`: validated once; "
              "the stop time, the controllers' period and the recording interval are held as "
              "integer numbers of steps).", "",
              "| key | default | unit | meaning |", "|---|---|---|---|"]
    for key, (default, unit, text) in COSIM_KEYS.items():
        ds = "-" if default is None else (f'"{default}"' if isinstance(default, str)
                                          else f"{default:g}")
        lines.append(f"| {key} | {ds} | {unit} | {text} |")
    lines += ["", "## Overrides", "",
              "Any key can be overridden without editing a file, by its *key path*: `KEY` for "
              "a top-level key (`gravity`, `model`, `outputs`, `description`, `loads`), "
              "`TABLE.KEY` for a key of a table (`pipe.length`, `controller.gain`, "
              "`top_drive_controller.p_gain`, `cosim.actuator_delay`, ...). The same key paths "
              "serve `drillcosim run --set KEY=VALUE` (value in TOML syntax), "
              "`drillcosim.simulate(overrides={...})`, sweeps (`--set`) and the calibration. "
              "An unknown key path or a bad value is one line naming the key and what is "
              "allowed (exit code 2).", ""]
    return "\n".join(lines)

"""The scene file schema as markdown (``drillcosim schema``, ``docs/scenes.md``): the plant's
tables (:func:`plant.scene.schema_markdown`), then those of the co-simulation
(:func:`cosim_schema_markdown`: ``[plant]``, ``[controller]``, ``[top_drive_controller]``,
``[cosim]``), and how overrides name keys."""

from __future__ import annotations

import math
from dataclasses import fields
from typing import Any

from drillcosim.controller import TABLES, default_kind, kinds, law_named
from drillcosim.plant.scene import schema_markdown

from .config import COSIM_KEYS

__all__ = ["cosim_schema_markdown", "scene_schema"]

#: What a law table is for, by table.
_TABLE_TEXT = {
    "controller": "The strain controller: gauges -> bending actuators (`[controller] kind`, "
                  "one of the registered laws, `controller/registry.py`).",
    "top_drive_controller": "The top-drive controller: drive speed and top torque -> motor "
                            "torque; needs `[top_drive] mode = \"torque\"` (docs/physics.md "
                            "section 6).",
}


def scene_schema() -> str:
    """The whole scene schema (plant tables, then the co-simulation's) as markdown."""
    return schema_markdown() + "\n" + cosim_schema_markdown()


def _default_text(d: Any) -> str:
    """A default value as the schema tables show it."""
    if isinstance(d, tuple):
        return str(list(d))
    return ("inf" if isinstance(d, float) and math.isinf(d) else
            str(d).lower() if isinstance(d, bool) else f'"{d}"' if isinstance(d, str)
            else f"{d:g}")


def _law_table(table: str) -> list[str]:
    """The markdown of one law table: its common keys, then each law's keys (from the law's
    parameters' field metadata: the same words its FMU's variables carry)."""
    laws = [law_named(k) for k in kinds(table)]
    cli = "; `drillcosim run --controller-fmu` overrides it" if table == "controller" else ""
    lines = [f"## [{table}]", "", _TABLE_TEXT.get(table, ""), "",
             "| key | default | unit | meaning |", "|---|---|---|---|",
             f"| kind | \"{default_kind(table)}\" | - | the law: "
             f"{', '.join(repr(law.KIND) for law in laws)} (below) |",
             f"| enabled | false | - | false = no {table} (the plant runs without it) |",
             f"| fmu | - | - | path of an FMU of any maker (relative to the scene file's folder) "
             f"instead of the project's{cli} |",
             f"| parameters | - | - | `[{table}.parameters]` NAME = value: that FMU's own "
             f"parameters, checked against its modelDescription before the first step (also "
             f"`--set {table}.parameters.NAME=VALUE`) |", ""]
    for law in laws:
        lines += [f"### kind = \"{law.KIND}\"", "",
                  f"{law.DESCRIPTION} (`{law.__module__.replace('drillcosim.', '')}."
                  f"{law.__name__}`, its FMU {law.FMU}.fmu).", ""]
        rows = [f for f in fields(law.PARAMS) if "doc" in f.metadata] \
            if not law.RESOURCE else []
        if law.RESOURCE:
            lines += ["| key | default | unit | meaning |", "|---|---|---|---|",
                      "| matrices | - | - | the law's file (`controller.state_space` JSON: "
                      "matrices, signals, limits, sample period), relative to the scene file; "
                      "its FMU is built for the scene and carries it |", ""]
            continue
        lines += ["| key | default | unit | meaning |", "|---|---|---|---|"]
        for f in rows:
            if f.name == "enabled":
                continue
            meta = f.metadata
            unit = meta["unit"].replace(".", " ") or "-"
            choices = meta.get("choices")
            doc = meta["doc"] + (f" (one of {', '.join(map(repr, choices))})" if choices else "")
            lines.append(f"| {f.name} | {_default_text(f.default)} | {unit} | "
                         f"{doc.replace('|', chr(92) + '|')} |")
        lines.append("")
    return lines


def cosim_schema_markdown() -> str:
    """The ``[plant]``, law tables (``[controller]``, ``[top_drive_controller]``) and
    ``[cosim]`` tables as markdown (for ``docs/scenes.md``)."""
    lines = ["## [plant]", "",
             "Which plant FMU runs the scene (`cosim.scenario.config`).", "",
             "| key | default | unit | meaning |", "|---|---|---|---|",
             "| fmu | - | - | path of a plant FMU (any maker; relative to the scene file's "
             "folder) instead of the built DrillstringPlant.fmu; `drillcosim run --plant-fmu` "
             "overrides it |",
             "| parameters | - | - | `[plant.parameters]` NAME = value: that FMU's own "
             "parameters (checked against its modelDescription before the first step) |", ""]
    for table in TABLES:
        lines += _law_table(table)
    lines += ["The plant and controller FMUs connect by name; before the first step the "
              "system is checked (causality, type, unit, nothing connected twice, start values "
              "and their declared ranges), every problem in one line naming both FMUs and the "
              "variable (exit code 2). Plant inputs of sites the controller does not serve "
              "keep their start value, with a warning naming them ([interop.md](interop.md)). "
              "A foreign FMU gets the law's keys it declares a parameter of that name for; "
              "one it does not declare is not required of it (a warning names it), unless an "
              "override sets it ([your_own_controller.md](your_own_controller.md)).", "",
              "## [cosim]", "",
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
              "`top_drive_controller.p_gain`, `cosim.actuator_delay`, ...), "
              "`TABLE.parameters.NAME` for a foreign FMU's own parameter "
              "(`controller.parameters.kd`). The same key paths "
              "serve `drillcosim run --set KEY=VALUE` (value in TOML syntax), "
              "`drillcosim.simulate(overrides={...})`, sweeps (`--set`) and the calibration. "
              "An unknown key path or a bad value is one line naming the key and what is "
              "allowed (exit code 2).", ""]
    return "\n".join(lines)

"""The side file of an exported run (`addtc export` writes it, the import reads it back): its format
name, the parameter that names it, the controller prefix of exact behaviours, its top-level keys
(the exporter writes exactly these: tests/unit/interop/test_xosc_export.py), and its check."""

import json

from addt_dsl import units
from addt_dsl.confine import Refused, confine
from addt_dsl.interop.openscenario.params import EXPR
from addt_dsl.plan import LIGHT_PROGRAM, LIGHT_STATES, ClausePlan, ConcreteFault, OraclePlan, TriggerPlan
from addt_dsl.vehicles import VEHICLES

SIDECAR_FORMAT = "addt-xosc-sidecar/1"  # the side file's "format"
SIDECAR_PARAM = "addt_sidecar"  # the OpenSCENARIO parameter that names the side file
CONTROLLER_PREFIX = "addt_"  # a controller named addt_<behaviour>: that behaviour, its settings as properties
# The side file's top-level keys: containers (with their JSON type), texts, and the rest.
SIDE_FILE_CONTAINERS = (("actors", dict), ("behaviors", dict), ("conditions", dict), ("groups", dict),
                        ("faults", list), ("oracles", list), ("params", dict), ("param_dims", dict),
                        ("group_events", list), ("holds", dict))
SIDE_FILE_TEXTS = ("scenario", "description", "source_file", "run_id")
SIDE_FILE_KEYS = ("format", *SIDE_FILE_TEXTS, "step_s", "seed", "run_seed", *(k for k, _ in SIDE_FILE_CONTAINERS),
                  "lights")


def sidecar_problem(data: dict) -> str:
    """What is wrong with a side file's contents ("" if nothing): each part is validated
    before the import uses it, so a damaged file is a diagnostic, not an exception."""
    try:
        for key, kind in SIDE_FILE_CONTAINERS:
            if not isinstance(data.get(key, kind()), kind):
                return f"'{key}' is not a {kind.__name__}"
        for key in SIDE_FILE_TEXTS:
            if not isinstance(data.get(key, ""), str):
                return f"'{key}' is not a string"
        for info in data.get("actors", {}).values():
            if info.get("vehicle") not in VEHICLES:
                return f"unknown vehicle {info.get('vehicle')!r}"
            for key in ("length_m", "width_m", "height_m", "mass_kg", "wheelbase_m", "goal_s", "mu", "yaw"):
                if info.get(key) is not None:
                    float(info[key])
            if not isinstance(info.get("reverse", False), bool):
                return "an actor's 'reverse' is not true or false"
            if (info.get("mass_kg") is None) != (info.get("wheelbase_m") is None):
                return "an actor's 'mass_kg' and 'wheelbase_m' come together"
            route = info.get("route", [])
            if not isinstance(route, list) or not all(type(r) in (str, int) for r in route):
                return "an actor's 'route' is not a list of road ids"
            if info.get("stack"):
                ClausePlan.model_validate(info["stack"])
            for x in info.get("sensors", []):
                ClausePlan.model_validate(x)
        for b in data.get("behaviors", {}).values():
            ClausePlan.model_validate(b["clause"])
        for c in data.get("conditions", {}).values():
            EXPR.validate_python(c["formula"])
        for steps in data.get("groups", {}).values():
            for step in steps:
                TriggerPlan.model_validate(step)
        lights = data.get("lights", {})
        if not isinstance(lights, dict):
            return "'lights' is not a dict"
        for c in lights.get("controllers", {}).values():
            for key in ("green_s", "yellow_s", "red_s", "offset_s"):
                float(c[key])
        for clause in lights.get("steps", {}).values():
            step = ClausePlan.model_validate(clause)
            if step.keyword != "light" or step.settings.get("state") not in (*LIGHT_STATES, LIGHT_PROGRAM):
                return "a light step that is not a `light` clause with a state"
        for f in data.get("faults", []):
            ConcreteFault.model_validate(f)
        for o in data.get("oracles", []):
            OraclePlan.model_validate(o)
        for k, v in data.get("params", {}).items():
            float(v)
        for d in data.get("param_dims", {}).values():
            units.dim_from_name(d)
        float(data.get("step_s", 0.01))
        # int(1.5) is 1: a seed must be a whole number as written (run_seed may be absent: null).
        for key, value in (("seed", data.get("seed", 0)), ("run_seed", data.get("run_seed"))):
            if type(value) is not int and not (key == "run_seed" and value is None):
                return f"'{key}' is {value!r}, not an integer"
    except (ValueError, TypeError, KeyError, AttributeError) as exc:  # pydantic's ValidationError is a ValueError
        return (str(exc).splitlines() or [type(exc).__name__])[0][:200]
    return ""


class SideFile:
    # -- side file of an exported run

    def load_sidecar(self, decls, header) -> None:
        name = self.params[SIDECAR_PARAM][1]
        try:
            confine(name, self.path.parent, self.root)
        except Refused as refused:
            self.approx(decls, f"side file {name}: {refused.message}; the ego's stack and sensors, the faults, "
                               "oracles and exact behaviours it carries are not imported")
            return
        got = self.read(name, self.path.parent, decls)
        if got is None:
            return
        try:
            data = json.loads(got[1])
        except ValueError as exc:
            self.error(decls, f"side file {name} is not JSON: {exc}")
            return
        if not isinstance(data, dict) or data.get("format") != SIDECAR_FORMAT:
            self.error(decls, f"side file {name} is not an addt-dsl export side file ({SIDECAR_FORMAT})")
            return
        problem = sidecar_problem(data)
        if problem:
            self.error(decls, f"side file {name} is not what addtc export writes: {problem}")
            return
        # `addtc export` names the scenario in the FileHeader and in the side file: a side
        # file of another export would bring its stack, faults and oracles into this one.
        written_for = header.get("description") if header is not None else None
        if written_for and data.get("scenario") and written_for != data["scenario"]:
            self.error(decls, f"side file {name} was written for scenario {data['scenario']!r}, but this file is "
                              f"scenario {written_for!r}: it belongs to another export; export the run again, or "
                              f"remove the `{SIDECAR_PARAM}` parameter to import the OpenSCENARIO alone")
            return
        self.sidecar = data

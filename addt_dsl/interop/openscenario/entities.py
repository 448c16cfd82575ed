"""Entities: vehicles, pedestrians and objects, inline or from catalogs, as actors; vehicle categories."""

import math
import os
import re
from pathlib import Path

from addt_dsl import units
from addt_dsl.interop.openscenario.params import NAME_RE
from addt_dsl.interop.openscenario.xml import Stop, child_at, only_child
from addt_dsl.vehicles import VEHICLES

CATEGORY_KIND = {"car": "car", "van": "car", "motorbike": "cyclist", "bicycle": "cyclist", "bus": "truck",
                 "truck": "truck", "semitrailer": "truck", "trailer": "truck", "train": "truck", "tram": "truck"}


def safe_name(name: str, taken: set[str]) -> str:
    base = re.sub(r"\W", "_", name) or "actor"
    if not NAME_RE.fullmatch(base):
        base = f"a_{base}"
    out, i = base, 2
    while out in taken:
        out, i = f"{base}_{i}", i + 1
    return out


class Entities:
    # -- entities

    def entities(self, root) -> None:
        objects = list(root.iterfind("Entities/ScenarioObject"))
        names = [o.get("name", "") for o in objects]
        ego = next((n for n in names if n.lower() in ("ego", "hero")), None)
        if ego is None and names:
            ego = names[0]
            self.approx(objects[0], f"no entity named Ego: '{ego}' becomes the ego (driven by the stack)")
        taken: set[str] = set()
        for obj, name in zip(objects, names):
            addt = "ego" if name == ego else safe_name(name, taken | {"ego"})
            taken.add(addt)
            self.renames[name] = addt
        for obj in objects:
            self.entity(obj, self.renames[obj.get("name", "")])
        for sel in root.iterfind("Entities/EntitySelection"):
            self.skip(sel, "entity selections are not translated")
        if "ego" not in self.actors:
            self.error(root.find("Entities"), "no entity to be the ego")
            raise Stop

    def entity(self, obj, name: str) -> None:
        body = only_child(obj) if obj.find("ObjectController") is None else \
            next((c for c in obj if c.tag != "ObjectController"), None)
        saved = dict(self.params)
        if body is not None and body.tag == "CatalogReference":
            ref = body
            body = self.catalog_entry(ref)
            # The entry's own parameters, as the reference assigns them.
            for decl in body.iterfind("ParameterDeclarations/ParameterDeclaration") if body is not None else ():
                self.params[decl.get("name", "")] = (decl.get("parameterType", "string"), decl.get("value", ""))
            for assign in ref.iterfind("ParameterAssignments/ParameterAssignment"):
                self.params[assign.get("parameterRef", "")] = ("string", assign.get("value", ""))
        try:
            self.entity_body(obj, name, body)
        finally:
            self.params = saved

    def entity_body(self, obj, name: str, body) -> None:
        kind, length, width = "car", None, None
        if body is None:
            self.approx(obj, f"entity '{obj.get('name')}': no vehicle definition; a default car")
        elif body.tag == "Vehicle":
            category = self.raw(body, "vehicleCategory", required=False) or "car"
            kind = CATEGORY_KIND.get(category, "car")
        elif body.tag == "Pedestrian":
            kind = "pedestrian"
        elif body.tag == "MiscObject":
            kind = "obstacle"
        else:
            self.skip(body, f"<{body.tag}> '{obj.get('name')}' is not translated")
            return
        dims = child_at(body, "BoundingBox", "Dimensions") if body is not None else None
        height = None
        if dims is not None:
            length, width = self.value(dims, "length"), self.value(dims, "width")
            height = self.value(dims, "height") if dims.get("height") is not None else None
        # The box centre ahead of the reference point (where the importer puts the actor's
        # centre) [m]: distances between boxes (free space) measure from the box.
        centre = child_at(body, "BoundingBox", "Center") if body is not None else None
        box_x = self.value(centre, "x") if centre is not None and centre.get("x") is not None else 0.0
        if self.sidecar and name in self.sidecar.get("actors", {}):
            kind = self.sidecar["actors"][name]["vehicle"]
        if name == "ego" and kind != "car":
            self.approx(obj, f"the ego is a {kind} in the scenario; addt-dsl's stack drives a car")
            kind = "car"
        # The catalog's Performance bounds every speed change (esmini clamps the acceleration
        # of SpeedActions to it, and DynamicConstraints): [m/s^2], [m/s]; None without one.
        perf = body.find("Performance") if body is not None and body.tag == "Vehicle" else None
        limits = {}
        for attr, key, dim in (("maxAcceleration", "max_accel", units.ACCELERATION),
                               ("maxDeceleration", "max_decel", units.ACCELERATION),
                               ("maxSpeed", "max_speed", units.SPEED)):
            if perf is not None and perf.get(attr) is not None:
                value = self.value(perf, attr, dim)
                if value > 0 and math.isfinite(value):
                    limits[key] = value
        self.actors[name] = {**limits, "vehicle": kind, "length_m": length if length and length > 0 else None,
                             "width_m": width if width and width > 0 else None,
                             "height_m": height if height and 0.05 <= height <= 10.0 else None, "el": obj,
                             "box_x_m": box_x if math.isfinite(box_x) else 0.0,
                             "behaviors": [], "triggers": [], "lane_now": None, "speed_now": 0.0}

    def catalog_entry(self, ref, kinds=("Vehicle", "Pedestrian", "MiscObject")):
        catalog, entry = self.raw(ref, "catalogName"), self.raw(ref, "entryName")
        locations = {loc.tag.removesuffix("Catalog"): loc.find("Directory")
                     for loc in self.doc.iterfind("CatalogLocations/*")}
        for kind in kinds:
            directory = locations.get(kind)
            if directory is None:
                continue
            base = self.raw(directory, "path")
            folder = self.path.parent / base
            if not self.inside(folder):
                continue
            for candidate in sorted(folder.glob("*.xosc"))[:64]:
                if candidate not in self.catalog_docs:  # each catalog file read and parsed once
                    got = self.read(os.path.relpath(candidate, self.path.parent), self.path.parent, ref)
                    self.catalog_docs[candidate] = self.parse(got[1], candidate.name) if got is not None else None
                root = self.catalog_docs[candidate]
                for el in root.iterfind(f"Catalog/{kind}") if root is not None else ():
                    if el.get("name") == entry:
                        return el
        if "Route" in kinds or "Environment" in kinds or "Maneuver" in kinds:
            self.skip(ref, f"{kinds[0].lower()} '{entry}' of catalog {catalog} not found",
                      "catalogs are read from <CatalogLocations> inside the root directory")
            return None
        self.approx(ref, f"catalog entry '{entry}' of {catalog} not found: a default car "
                         f"({VEHICLES['car'].length_m} x {VEHICLES['car'].width_m} m)",
                    "catalogs are read from <CatalogLocations> inside the root directory")
        return None

    def inside(self, folder) -> bool:
        try:
            return Path(folder).resolve().is_relative_to(self.root) and Path(folder).is_dir()
        except OSError:
            return False

    def size(self, who: str) -> tuple[float, float]:
        info = self.actors[who]
        kind = VEHICLES[info["vehicle"]]
        return info["length_m"] or kind.length_m, info["width_m"] or kind.width_m

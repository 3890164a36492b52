#!/usr/bin/env python3
"""Writes small_scene.gltf next to this script (python3 standard library only).

A small glTF 2.0 scene for Specula: a ground plane and a pedestal carrying a mirror ball, a
turntable (animated: one turn about +Y every 8 s) carrying a glass sphere and a red box, a
perspective camera and a KHR_lights_punctual point light. The buffer is embedded (base64), so
the scene is one file.

    node tree                    mesh     material
    ground                       plane    ground   (grey, diffuse)
    pedestal                     box      stone    (diffuse)
      mirror ball                sphere   mirror   (metallic 1, roughness 0: reflective)
    turntable (animated)         -
      glass sphere               sphere   glass    (KHR_materials_transmission 1, ior 1.5)
      red box                    box      red      (diffuse)
    camera                       -        (perspective, yfov 0.8)
    lamp                         -        (point light, 60 cd)

Run `python3 samples/scenes/make_small_scene.py` after editing; commit the script and its output.
"""

import base64
import json
import math
import os
import struct

FLOAT, USHORT = 5126, 5123
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


class Builder:
    def __init__(self):
        self.bin = bytearray()
        self.views = []
        self.accessors = []

    def _view(self, data, target=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target is not None:
            view["target"] = target
        self.views.append(view)
        self.bin += data
        return len(self.views) - 1

    def vec3s(self, points):
        flat = [c for p in points for c in p]
        view = self._view(struct.pack("<%df" % len(flat), *flat), ARRAY_BUFFER)
        self.accessors.append({
            "bufferView": view, "componentType": FLOAT, "count": len(points), "type": "VEC3",
            "min": [min(p[i] for p in points) for i in range(3)],
            "max": [max(p[i] for p in points) for i in range(3)]})
        return len(self.accessors) - 1

    def scalars(self, values, fmt="f", component=FLOAT, target=None):
        data = struct.pack("<%d%s" % (len(values), fmt), *values)
        view = self._view(data, target)
        acc = {"bufferView": view, "componentType": component, "count": len(values),
               "type": "SCALAR"}
        if component == FLOAT:
            acc["min"], acc["max"] = [min(values)], [max(values)]
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def vec4s(self, quads):
        flat = [c for q in quads for c in q]
        view = self._view(struct.pack("<%df" % len(flat), *flat))
        self.accessors.append({"bufferView": view, "componentType": FLOAT, "count": len(quads),
                               "type": "VEC4"})
        return len(self.accessors) - 1

    def mesh(self, name, positions, normals, indices, material):
        return {"name": name, "primitives": [{
            "attributes": {"POSITION": self.vec3s(positions), "NORMAL": self.vec3s(normals)},
            "indices": self.scalars(indices, "H", USHORT, ELEMENT_ARRAY_BUFFER),
            "material": material}]}


def plane(size):
    h = size / 2
    positions = [(-h, 0, -h), (-h, 0, h), (h, 0, h), (h, 0, -h)]
    return positions, [(0, 1, 0)] * 4, [0, 1, 2, 0, 2, 3]


def box(sx, sy, sz):
    """Axis-aligned box centred at the origin, 4 vertices per face (flat normals)."""
    positions, normals, indices = [], [], []
    for axis in range(3):
        for sign in (1, -1):
            n = [0, 0, 0]
            n[axis] = sign
            u = [0, 0, 0]
            v = [0, 0, 0]
            u[(axis + 1) % 3] = 1
            v[(axis + 2) % 3] = 1
            base = len(positions)
            for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [n[i] + a * u[i] + b * v[i] for i in range(3)]
                positions.append((p[0] * sx / 2, p[1] * sy / 2, p[2] * sz / 2))
                normals.append(tuple(n))
            # Counter-clockwise seen from outside: u × v = n for sign +1.
            quad = [0, 1, 2, 0, 2, 3] if sign > 0 else [0, 2, 1, 0, 3, 2]
            indices += [base + i for i in quad]
    return positions, normals, indices


def sphere(radius, segments=24, rings=12):
    positions, normals, indices = [], [], []
    for r in range(rings + 1):
        theta = math.pi * r / rings
        for s in range(segments + 1):
            phi = 2 * math.pi * s / segments
            n = (math.sin(theta) * math.cos(phi), math.cos(theta), -math.sin(theta) * math.sin(phi))
            normals.append(n)
            positions.append(tuple(radius * c for c in n))
    for r in range(rings):
        for s in range(segments):
            a = r * (segments + 1) + s
            b = a + segments + 1
            if r != 0:
                indices += [a, b, a + 1]
            if r != rings - 1:
                indices += [a + 1, b, b + 1]
    return positions, normals, indices


def quat_axis_angle(axis, radians):
    s = math.sin(radians / 2)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(radians / 2)]


def main():
    b = Builder()
    materials = [
        {"name": "ground", "pbrMetallicRoughness": {
            "baseColorFactor": [0.6, 0.6, 0.6, 1], "metallicFactor": 0, "roughnessFactor": 1}},
        {"name": "stone", "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.78, 0.72, 1], "metallicFactor": 0, "roughnessFactor": 0.9}},
        {"name": "mirror", "pbrMetallicRoughness": {
            "baseColorFactor": [0.95, 0.95, 0.95, 1], "metallicFactor": 1, "roughnessFactor": 0}},
        {"name": "glass", "pbrMetallicRoughness": {
            "baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
         "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1},
                        "KHR_materials_ior": {"ior": 1.5}}},
        {"name": "red", "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0, "roughnessFactor": 0.6}},
    ]
    meshes = [
        b.mesh("plane", *plane(12), material=0),
        b.mesh("pedestal", *box(1.2, 1, 1.2), material=1),
        b.mesh("mirror ball", *sphere(0.5), material=2),
        b.mesh("glass sphere", *sphere(0.6), material=3),
        b.mesh("red box", *box(0.8, 0.8, 0.8), material=4),
    ]
    # Camera at (0, 3, 8) looking at (0, 0.8, 0): tilt down about +X.
    tilt = -math.atan2(3 - 0.8, 8)
    nodes = [
        {"name": "ground", "mesh": 0},
        {"name": "pedestal", "translation": [0, 0.5, 0], "mesh": 1, "children": [2]},
        {"name": "mirror ball", "translation": [0, 1.0, 0], "mesh": 2},
        {"name": "turntable", "children": [4, 5]},
        {"name": "glass sphere", "translation": [2.2, 0.6, 0], "mesh": 3},
        {"name": "red box", "translation": [-2.2, 0.4, 0],
         "rotation": quat_axis_angle((0, 1, 0), math.radians(30)), "mesh": 4},
        {"name": "camera", "translation": [0, 3, 8],
         "rotation": quat_axis_angle((1, 0, 0), tilt), "camera": 0},
        {"name": "lamp", "translation": [2, 5, 3],
         "extensions": {"KHR_lights_punctual": {"light": 0}}},
    ]
    # One turn about +Y in 8 s, as 5 keys 90° apart (LINEAR slerp takes the short way).
    times = [0, 2, 4, 6, 8]
    rotations = [quat_axis_angle((0, 1, 0), math.radians(90 * k)) for k in range(5)]
    animation = {"name": "turn", "samplers": [{
        "input": b.scalars(times), "output": b.vec4s(rotations), "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": 3, "path": "rotation"}}]}

    doc = {
        "asset": {"version": "2.0", "generator": "samples/scenes/make_small_scene.py"},
        "extensionsUsed": ["KHR_lights_punctual", "KHR_materials_transmission",
                           "KHR_materials_ior"],
        "scene": 0,
        "scenes": [{"name": "small scene", "nodes": [0, 1, 3, 6, 7]}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "cameras": [{"type": "perspective", "perspective": {
            "yfov": 0.8, "aspectRatio": 4 / 3, "znear": 0.1, "zfar": 100}}],
        "extensions": {"KHR_lights_punctual": {"lights": [
            {"name": "lamp", "type": "point", "color": [1, 0.95, 0.85], "intensity": 60}]}},
        "animations": [animation],
        "accessors": b.accessors,
        "bufferViews": b.views,
        "buffers": [{"byteLength": len(b.bin), "uri": "data:application/octet-stream;base64," +
                     base64.b64encode(bytes(b.bin)).decode()}],
    }
    out = os.path.join(os.path.dirname(os.path.abspath(__file__)), "small_scene.gltf")
    with open(out, "w") as f:
        json.dump(doc, f, indent=1)
        f.write("\n")


if __name__ == "__main__":
    main()

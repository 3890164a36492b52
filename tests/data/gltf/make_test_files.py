#!/usr/bin/env python3
"""Writes the glTF test files of tests/scene/test_gltf.cpp (python3 standard library only).

Run from anywhere: `python3 tests/data/gltf/make_test_files.py`. The outputs are committed; the
script documents what each file holds (tests compare against the numbers written here).

Good files: hierarchy.gltf (nodes, materials, cameras, lights), animated.gltf (TRS and morph
animation, morphing normals included), sparse.gltf (sparse accessors), modes.gltf (strips, fans, points, quantized
positions), box.glb (binary).
Bad files: bad_*.gltf / bad_*.glb, one problem each (see BAD_FILES at the bottom).
"""

import base64
import json
import math
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

FLOAT, UBYTE, USHORT, UINT, SHORT = 5126, 5121, 5123, 5125, 5122
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


class Gltf:
    """A glTF document with one binary buffer that accessors are appended to."""

    def __init__(self):
        self.doc = {"asset": {"version": "2.0", "generator": "make_test_files.py"}}
        self.bin = bytearray()

    def _list(self, key):
        return self.doc.setdefault(key, [])

    def add(self, key, obj):
        items = self._list(key)
        items.append(obj)
        return len(items) - 1

    def view(self, data, target=None):
        while len(self.bin) % 4:
            self.bin.append(0)
        view = {"buffer": 0, "byteOffset": len(self.bin), "byteLength": len(data)}
        if target:
            view["target"] = target
        self.bin += data
        return self.add("bufferViews", view)

    def accessor(self, values, type_, component=FLOAT, target=None, normalized=False,
                 minmax=False):
        """values: flat list of numbers."""
        fmt = {FLOAT: "f", UBYTE: "B", USHORT: "H", UINT: "I", SHORT: "h"}[component]
        n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}[type_]
        view = self.view(struct.pack("<%d%s" % (len(values), fmt), *values), target)
        acc = {"bufferView": view, "componentType": component, "count": len(values) // n,
               "type": type_}
        if normalized:
            acc["normalized"] = True
        if minmax:
            acc["min"] = [min(values[i::n]) for i in range(n)]
            acc["max"] = [max(values[i::n]) for i in range(n)]
        return self.add("accessors", acc)

    def positions(self, points):
        return self.accessor([c for p in points for c in p], "VEC3", target=ARRAY_BUFFER,
                             minmax=True)

    def indices(self, idx, component=USHORT):
        return self.accessor(idx, "SCALAR", component, target=ELEMENT_ARRAY_BUFFER)

    def buffers_embedded(self):
        uri = "data:application/octet-stream;base64," + base64.b64encode(bytes(self.bin)).decode()
        self.doc["buffers"] = [{"byteLength": len(self.bin), "uri": uri}]

    def write_gltf(self, name, embed=True):
        if embed:
            self.buffers_embedded()
        with open(os.path.join(HERE, name), "w") as f:
            json.dump(self.doc, f, indent=1)
            f.write("\n")

    def glb_bytes(self):
        self.doc["buffers"] = [{"byteLength": len(self.bin)}]
        text = json.dumps(self.doc).encode()
        text += b" " * (-len(text) % 4)
        binary = bytes(self.bin) + b"\0" * (-len(self.bin) % 4)
        total = 12 + 8 + len(text) + 8 + len(binary)
        out = struct.pack("<4sII", b"glTF", 2, total)
        out += struct.pack("<II", len(text), 0x4E4F534A) + text
        out += struct.pack("<II", len(binary), 0x004E4942) + binary
        return out


def quat_axis_angle(axis, degrees):
    """glTF order: x, y, z, w."""
    half = math.radians(degrees) / 2
    s = math.sin(half)
    return [axis[0] * s, axis[1] * s, axis[2] * s, math.cos(half)]


QUAD = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
QUAD_INDICES = [0, 1, 2, 0, 2, 3]


def add_quad_mesh(g, material=None, name="quad"):
    pos = g.positions(QUAD)
    nrm = g.accessor([0, 0, 1] * 4, "VEC3", target=ARRAY_BUFFER)
    idx = g.indices(QUAD_INDICES)
    prim = {"attributes": {"POSITION": pos, "NORMAL": nrm}, "indices": idx}
    if material is not None:
        prim["material"] = material
    return g.add("meshes", {"name": name, "primitives": [prim]})


def write_hierarchy():
    """Node tree with known transforms; three materials; cameras; three light types."""
    g = Gltf()
    g.doc["extensionsUsed"] = ["KHR_lights_punctual", "KHR_materials_transmission",
                               "KHR_materials_ior", "KHR_materials_emissive_strength"]
    g.add("materials", {"name": "mirror", "pbrMetallicRoughness": {
        "baseColorFactor": [0.9, 0.9, 0.9, 1], "metallicFactor": 1, "roughnessFactor": 0}})
    g.add("materials", {"name": "glass", "pbrMetallicRoughness": {
        "baseColorFactor": [1, 1, 1, 1], "metallicFactor": 0, "roughnessFactor": 0},
        "extensions": {"KHR_materials_transmission": {"transmissionFactor": 0.9},
                       "KHR_materials_ior": {"ior": 1.33}}})
    g.add("materials", {"name": "glow", "pbrMetallicRoughness": {
        "baseColorFactor": [0.2, 0.4, 0.6, 1], "metallicFactor": 0.5, "roughnessFactor": 0.5},
        "emissiveFactor": [1, 0.5, 0.25],
        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}}})
    add_quad_mesh(g, material=0)  # mesh 0
    # mesh 1: three triangles without normals, materials glass, glow, glass → two groups.
    prims = []
    for k, material in enumerate([1, 2, 1]):
        tri = [(k, 0, 0), (k + 1, 0, 0), (k, 1, 0)]
        prims.append({"attributes": {"POSITION": g.positions(tri)}, "material": material})
    g.add("meshes", {"name": "two materials", "primitives": prims})

    # Column-major matrix of T(0,1,0)·Rx(90°)·S(0.5).
    child_matrix = [0.5, 0, 0, 0,
                    0, 0, 0.5, 0,
                    0, -0.5, 0, 0,
                    0, 1, 0, 1]
    g.doc["nodes"] = [
        {"name": "root", "translation": [1, 2, 3], "rotation": quat_axis_angle((0, 1, 0), 90),
         "scale": [2, 2, 2], "mesh": 0, "children": [1, 3, 5]},                       # 0
        {"name": "child", "matrix": child_matrix, "mesh": 0, "children": [2]},        # 1
        {"translation": [0, 0, -1], "mesh": 1},                                       # 2
        {"name": "camera", "translation": [0, 0, 5], "camera": 0},                    # 3
        {"name": "sun", "rotation": quat_axis_angle((1, 0, 0), -90),
         "extensions": {"KHR_lights_punctual": {"light": 0}}},                        # 4
        {"name": "spot", "translation": [0, 3, 0],
         "extensions": {"KHR_lights_punctual": {"light": 1}}},                        # 5
        {"name": "lamp", "translation": [0, 4, 0],
         "extensions": {"KHR_lights_punctual": {"light": 2}}},                        # 6
        {"name": "other scene", "mesh": 0},                                           # 7
        {"name": "ortho", "camera": 1},                                               # 8
    ]
    g.doc["cameras"] = [
        {"type": "perspective", "perspective": {"yfov": 0.8, "aspectRatio": 1.5, "znear": 0.1}},
        {"type": "orthographic",
         "orthographic": {"xmag": 1, "ymag": 1, "znear": 0.1, "zfar": 100}},
    ]
    g.doc["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "directional", "color": [1, 0.9, 0.8], "intensity": 3},
        {"type": "spot", "intensity": 50, "range": 10,
         "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}},
        {"type": "point", "intensity": 100},
    ]}}
    g.doc["scenes"] = [{"nodes": [0, 4, 6, 8]}, {"nodes": [7]}]
    g.doc["scene"] = 0
    g.write_gltf("hierarchy.gltf")


def write_animated():
    """TRS animation (LINEAR, STEP, CUBICSPLINE) and morph-weight animation."""
    g = Gltf()
    add_quad_mesh(g)  # mesh 0
    tri = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]
    base = g.positions(tri)
    target0 = g.accessor([0, 0, 1] * 3, "VEC3")                # every vertex +Z
    target1 = g.accessor([1, 0, 0, 0, 0, 0, 0, 0, 0], "VEC3")  # vertex 0 +X
    g.add("meshes", {"name": "morph", "weights": [0, 0], "primitives": [{
        "attributes": {"POSITION": base}, "targets": [{"POSITION": target0},
                                                      {"POSITION": target1}]}]})  # mesh 1
    # Normals that morph: every normal +Z; target 0 adds (0, 1, -1) to each (+Y at weight 1),
    # target 1 has no NORMAL (zeros); its POSITION moves vertex 2 by +Z.
    bent_normals = g.accessor([0, 0, 1] * 3, "VEC3")
    bent_target0 = g.accessor([0, 1, -1] * 3, "VEC3")
    bent_target1 = g.accessor([0, 0, 0, 0, 0, 0, 0, 0, 1], "VEC3")
    g.add("meshes", {"name": "bent", "primitives": [{
        "attributes": {"POSITION": base, "NORMAL": bent_normals},
        "targets": [{"NORMAL": bent_target0}, {"POSITION": bent_target1}]}]})  # mesh 2
    g.doc["nodes"] = [
        {"name": "mover", "mesh": 0, "children": [1]},                  # 0
        {"name": "rider", "translation": [0, 1, 0], "mesh": 0},         # 1
        {"name": "still", "translation": [5, 0, 0], "mesh": 0},         # 2
        {"name": "blob", "mesh": 1},                                    # 3
        {"name": "posed", "mesh": 1, "weights": [1, 0]},                # 4
        {"name": "bender", "mesh": 2},                                  # 5
        {"name": "leaning", "mesh": 2, "weights": [0.5, 0]},            # 6
    ]
    t3 = g.accessor([0, 1, 2], "SCALAR", minmax=True)
    t2 = g.accessor([0, 1], "SCALAR", minmax=True)
    translation = g.accessor([0, 0, 0, 1, 0, 0, 1, 2, 0], "VEC3")
    rotation = g.accessor([0, 0, 0, 1] + quat_axis_angle((0, 0, 1), 90), "VEC4")
    # CUBICSPLINE: (in-tangent, value, out-tangent) per key; tangents are junk on purpose.
    scale = g.accessor([9, 9, 9, 1, 1, 1, 9, 9, 9, 9, 9, 9, 2, 2, 2, 9, 9, 9], "VEC3")
    weights = g.accessor([0, 0, 1, 0, 0.5, 1], "SCALAR")
    bent_weights = g.accessor([0, 0, 1, 0, 0.5, 1], "SCALAR")
    other_translation = g.accessor([7, 7, 7, 8, 8, 8], "VEC3")
    g.doc["animations"] = [
        {"name": "main",
         "samplers": [{"input": t3, "output": translation, "interpolation": "LINEAR"},
                      {"input": t2, "output": rotation, "interpolation": "STEP"},
                      {"input": t2, "output": scale, "interpolation": "CUBICSPLINE"},
                      {"input": t3, "output": weights},
                      {"input": t3, "output": bent_weights}],
         "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                      {"sampler": 1, "target": {"node": 0, "path": "rotation"}},
                      {"sampler": 2, "target": {"node": 0, "path": "scale"}},
                      {"sampler": 3, "target": {"node": 3, "path": "weights"}},
                      {"sampler": 4, "target": {"node": 5, "path": "weights"}}]},
        # A second clip on the same node and path: the first animation keeps it.
        {"name": "conflicting",
         "samplers": [{"input": t2, "output": other_translation}],
         "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}}]},
    ]
    g.doc["scenes"] = [{"nodes": [0, 2, 3, 4, 5, 6]}]
    g.doc["scene"] = 0
    g.write_gltf("animated.gltf")


def write_sparse():
    """Positions with a sparse substitution, and a sparse accessor without a bufferView."""
    g = Gltf()
    pos = g.positions([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    idx_view = g.view(struct.pack("<H", 1))
    val_view = g.view(struct.pack("<3f", 5, 5, 5))
    g.doc["accessors"][pos]["sparse"] = {
        "count": 1, "indices": {"bufferView": idx_view, "componentType": USHORT},
        "values": {"bufferView": val_view}}
    g.doc["accessors"][pos].pop("min")
    g.doc["accessors"][pos].pop("max")
    # Positions all zero except vertex 2 (no bufferView: zeros, then sparse values).
    idx2 = g.view(struct.pack("<B", 2) + b"\0\0\0")
    val2 = g.view(struct.pack("<3f", 0, 0, 3))
    zeros = g.add("accessors", {"componentType": FLOAT, "count": 3, "type": "VEC3", "sparse": {
        "count": 1, "indices": {"bufferView": idx2, "componentType": UBYTE},
        "values": {"bufferView": val2}}})
    base = g.positions([(0, 0, 0), (2, 0, 0), (0, 2, 0)])
    g.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}}]})
    g.add("meshes", {"primitives": [{"attributes": {"POSITION": base},
                                     "targets": [{"POSITION": zeros}]}], "weights": [1]})
    g.doc["nodes"] = [{"mesh": 0}, {"mesh": 1}]
    g.doc["scenes"] = [{"nodes": [0, 1]}]
    g.write_gltf("sparse.gltf")


def write_modes():
    """One mesh: a strip (4 vertices), a fan (5 vertices, quantized SHORT normalized positions),
    a point list (skipped), all in the z = 0 plane, counter-clockwise seen from +Z."""
    g = Gltf()
    g.doc["extensionsUsed"] = ["KHR_mesh_quantization"]
    g.doc["extensionsRequired"] = ["KHR_mesh_quantization"]
    strip = g.positions([(0, 0, 0), (1, 0, 0), (0, 1, 0), (1, 1, 0)])
    half = 16384  # 16384 / 32767 ≈ 0.5
    fan_points = [(0, 0, 0), (half, 0, 0), (half, half, 0), (0, half, 0), (-half, half, 0)]
    # Quantized attributes start every element on 4 bytes: VEC3 of shorts with byteStride 8.
    fan = g.accessor([c for p in fan_points for c in p + (0,)], "VEC4", SHORT, normalized=True)
    g.doc["accessors"][fan]["type"] = "VEC3"
    g.doc["bufferViews"][g.doc["accessors"][fan]["bufferView"]]["byteStride"] = 8
    fan_idx = g.indices([0, 1, 2, 3, 4], UBYTE)
    points = g.positions([(0, 0, 0), (1, 1, 1)])
    g.add("meshes", {"primitives": [
        {"attributes": {"POSITION": strip}, "mode": 5},
        {"attributes": {"POSITION": fan}, "indices": fan_idx, "mode": 6},
        {"attributes": {"POSITION": points}, "mode": 0}]})
    g.doc["nodes"] = [{"name": "modes", "mesh": 0}]
    g.doc["scenes"] = [{"nodes": [0]}]
    g.write_gltf("modes.gltf")


def box_glb():
    """A binary file: a quad, a camera looking at it, no light."""
    g = Gltf()
    add_quad_mesh(g)
    g.doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1}}]
    g.doc["nodes"] = [{"name": "quad", "mesh": 0}, {"name": "eye", "translation": [0, 0, 4],
                                                    "camera": 0}]
    g.doc["scenes"] = [{"nodes": [0, 1]}]
    return g.glb_bytes()


def small_triangle(g, positions_bytes=None, indices=(0, 1, 2), count=3):
    """A one-triangle file; the positions' bytes and the accessor count can be broken."""
    data = positions_bytes or struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    view = g.view(data, ARRAY_BUFFER)
    pos = g.add("accessors", {"bufferView": view, "componentType": FLOAT, "count": count,
                              "type": "VEC3"})
    idx = g.indices(list(indices))
    g.add("meshes", {"primitives": [{"attributes": {"POSITION": pos}, "indices": idx}]})
    g.doc["nodes"] = [{"name": "triangle", "mesh": 0}]
    g.doc["scenes"] = [{"nodes": [0]}]
    return g


def write_bad_files():
    with open(os.path.join(HERE, "bad_json.gltf"), "w") as f:
        f.write('{"asset": {"version": "2.0"}, "nodes": [{"name": "x",}\n')

    glb = box_glb()
    with open(os.path.join(HERE, "bad_truncated.glb"), "wb") as f:
        f.write(glb[: len(glb) * 2 // 3])
    with open(os.path.join(HERE, "bad_magic.glb"), "wb") as f:
        f.write(b"glTX" + glb[4:])

    small_triangle(Gltf(), count=100).write_gltf("bad_accessor_range.gltf")
    small_triangle(Gltf(), indices=(0, 1, 7)).write_gltf("bad_index.gltf")
    nan = float("nan")
    small_triangle(Gltf(), struct.pack("<9f", 0, 0, 0, nan, 0, 0, 0, 1, 0)).write_gltf(
        "bad_nan.gltf")

    g = small_triangle(Gltf())
    g.doc["buffers"] = [{"byteLength": len(g.bin), "uri": "missing.bin"}]
    g.write_gltf("bad_missing_buffer.gltf", embed=False)

    g = small_triangle(Gltf())
    g.doc["nodes"] = [{"name": "a", "children": [1]}, {"name": "b", "children": [0]}]
    g.write_gltf("bad_cycle.gltf")

    g = small_triangle(Gltf())
    g.doc["nodes"] = [{"name": "a", "children": [9]}]
    g.write_gltf("bad_child_index.gltf")

    g = small_triangle(Gltf())
    g.doc["extensionsUsed"] = ["EXT_meshopt_compression"]
    g.doc["extensionsRequired"] = ["EXT_meshopt_compression"]
    g.write_gltf("bad_required_extension.gltf")

    g = small_triangle(Gltf())
    g.doc["extensionsUsed"] = ["KHR_draco_mesh_compression"]
    g.doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    g.write_gltf("bad_draco.gltf")

    small_triangle(Gltf(), count=10**12).write_gltf("bad_absurd_count.gltf")

    g = small_triangle(Gltf())
    g.doc["nodes"][0]["matrix"] = [1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    g.write_gltf("bad_singular_matrix.gltf")

    g = small_triangle(Gltf())
    normals = g.accessor([0, 0, 1] * 2, "VEC3", target=ARRAY_BUFFER)  # 2 normals, 3 vertices
    g.doc["meshes"][0]["primitives"][0]["attributes"]["NORMAL"] = normals
    g.write_gltf("bad_normal_count.gltf")

    g = small_triangle(Gltf())
    normals = g.accessor([0, 0, 1] * 3, "VEC3", target=ARRAY_BUFFER)
    cancel = g.accessor([0, 0, -1] * 3, "VEC3")  # weight 1 cancels every normal
    prim = g.doc["meshes"][0]["primitives"][0]
    prim["attributes"]["NORMAL"] = normals
    prim["targets"] = [{"NORMAL": cancel}]
    g.doc["meshes"][0]["weights"] = [1]
    g.write_gltf("bad_morph_normal.gltf")

    g = small_triangle(Gltf())
    times = g.accessor([0, 2, 1], "SCALAR")
    values = g.accessor([0, 0, 0, 1, 0, 0, 2, 0, 0], "VEC3")
    g.doc["animations"] = [{"samplers": [{"input": times, "output": values}], "channels": [
        {"sampler": 0, "target": {"node": 0, "path": "translation"}}]}]
    g.write_gltf("bad_animation_times.gltf")

    g = small_triangle(Gltf())
    g.doc["nodes"][0]["translation"] = [0, 1e300, 0]  # a finite double, but no float
    g.write_gltf("bad_huge_translation.gltf")

    # Two primitives with different materials, the second index past the end.
    g = small_triangle(Gltf())
    prim = g.doc["meshes"][0]["primitives"][0]
    g.doc["materials"] = [{"name": "only"}]
    prim["material"] = 0
    g.doc["meshes"][0]["primitives"].append(dict(prim, material=4))
    g.write_gltf("bad_material_index.gltf")

    g = small_triangle(Gltf())
    g.doc["extensionsUsed"] = ["KHR_lights_punctual"]
    g.doc["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point"}]}}
    g.doc["nodes"][0]["extensions"] = {"KHR_lights_punctual": {"light": 3}}
    g.write_gltf("bad_light_index.gltf")


def main():
    write_hierarchy()
    write_animated()
    write_sparse()
    write_modes()
    with open(os.path.join(HERE, "box.glb"), "wb") as f:
        f.write(box_glb())
    write_bad_files()


if __name__ == "__main__":
    main()

#!/usr/bin/env python3
"""Writes samples/scenes/dynamic_three_classes.json: the three kinematic classes animated at once.

A small scene in the spirit of the BART benchmark (Lext, Assarsson, Moller 2001), a few thousand
triangles, for `specula render --frames N --time T0:T1` and the frame-to-frame coherence tests:
  * static: a room (floor, three walls) and four pillars, never moved: built once, then untouched;
  * hierarchical: a toy car (body, four wheels, a turret with a spinning gun) driving a loop
    around the room's centre: its parent's keyframes move rigid children, so each frame costs only
    a top-level rebuild;
  * free: a waving flag (a grid whose vertices are keyed, a gentle deformation the refit absorbs)
    and a swarm of triangles that scatters from a ball into the room and gathers again (like
    BART's museum: its bounding boxes degrade, so the native BVH restructures subtrees).
The camera circles slowly along a camera path.

The swarm's scatter is drawn from a seeded generator: the file is the same on every run.
Python 3 standard library only. Run from anywhere:  python3 samples/scenes/make_dynamic_scene.py
"""

import json
import math
import os
import random

OUT = "dynamic_three_classes.json"
LINE_WIDTH = 100
DURATION = 4.0  # seconds; every animation loops over it
SEED = 11
FLAG_COLUMNS, FLAG_ROWS = 24, 12  # 576 triangles
SWARM_TRIANGLES = 384


def r4(v):
    """Short decimals keep the file readable; the loader reads them exactly as written."""
    v = round(v, 4)
    return 0.0 if v == 0 else v


def vec(v):
    return [r4(x) for x in v]


def quat_y(angle):
    """Rotation about +Y as [x, y, z, w]."""
    return [0.0, r4(math.sin(angle / 2)), 0.0, r4(math.cos(angle / 2))]


def quat_x(angle):
    return [r4(math.sin(angle / 2)), 0.0, 0.0, r4(math.cos(angle / 2))]


def track(times, values, interpolation="linear"):
    return {"interpolation": interpolation, "times": [r4(t) for t in times], "values": values}


def static_room():
    grey = {"base_color": [0.7, 0.7, 0.68]}
    walls = {"base_color": [0.55, 0.6, 0.7], "reflectivity": 0.15}
    entities = [
        {"name": "floor", "kinematics": "static",
         "mesh": {"primitive": "plane", "size": [12, 12], "subdivisions": 8}, "material": grey},
        {"name": "back wall", "kinematics": "static", "transform": {"translation": [0, 2, -6]},
         "mesh": {"primitive": "box", "size": [12, 4, 0.2]}, "material": walls},
        {"name": "left wall", "kinematics": "static", "transform": {"translation": [-6, 2, 0]},
         "mesh": {"primitive": "box", "size": [0.2, 4, 12]}, "material": walls},
        {"name": "right wall", "kinematics": "static", "transform": {"translation": [6, 2, 0]},
         "mesh": {"primitive": "box", "size": [0.2, 4, 12]}, "material": walls},
    ]
    for i, (x, z) in enumerate([(-4, -4), (4, -4), (-4, 4), (4, 4)]):
        entities.append({"name": f"pillar {i}", "kinematics": "static",
                         "transform": {"translation": [x, 1.5, z]},
                         "mesh": {"primitive": "cylinder", "radius": 0.35, "height": 3,
                                  "segments": 24},
                         "material": {"base_color": [0.8, 0.75, 0.6]}})
    return entities


def car():
    """A parent keyed around a loop (translation and heading), rigid children, one child keyed."""
    keys = 8
    times = [DURATION * k / keys for k in range(keys + 1)]
    radius = 2.6
    positions = [vec([radius * math.cos(2 * math.pi * k / keys), 0.35,
                      radius * math.sin(2 * math.pi * k / keys)]) for k in range(keys + 1)]
    # Heading along the circle's tangent: the car's +X points where it drives.
    headings = [quat_y(-2 * math.pi * k / keys - math.pi / 2) for k in range(keys + 1)]
    red = {"base_color": [0.8, 0.15, 0.1], "reflectivity": 0.3}
    black = {"base_color": [0.05, 0.05, 0.05]}
    entities = [{"name": "car", "kinematics": "hierarchical",
                 "transform": {"translation": positions[0]},
                 "mesh": {"primitive": "box", "size": [1.4, 0.4, 0.8]}, "material": red,
                 "animation": {"translation": track(times, positions),
                               "rotation": track(times, headings)}}]
    for i, (x, z) in enumerate([(-0.45, -0.45), (0.45, -0.45), (-0.45, 0.45), (0.45, 0.45)]):
        entities.append({"name": f"wheel {i}", "parent": "car", "kinematics": "hierarchical",
                         "transform": {"translation": [x, -0.15, z], "rotation": quat_x(math.pi / 2)},
                         "mesh": {"primitive": "cylinder", "radius": 0.18, "height": 0.12,
                                  "segments": 16},
                         "material": black})
    entities.append({"name": "turret", "parent": "car", "kinematics": "hierarchical",
                     "transform": {"translation": [0, 0.35, 0]},
                     "mesh": {"primitive": "sphere", "radius": 0.3, "segments": 16, "rings": 8},
                     "material": {"base_color": [0.9, 0.9, 0.9], "reflectivity": 0.6}})
    spin = [quat_y(2 * math.pi * k / 4) for k in range(5)]
    entities.append({"name": "gun", "parent": "turret", "kinematics": "hierarchical",
                     "transform": {"translation": [0.35, 0.05, 0]},
                     "mesh": {"primitive": "box", "size": [0.6, 0.08, 0.08]}, "material": black,
                     "animation": {"rotation": track([DURATION * k / 4 for k in range(5)], spin)}})
    return entities


def flag():
    """A grid hung from the back wall, waving: vertex keys of a travelling wave, with the wave's
    normals keyed beside them (smooth shading that follows the waves)."""
    w, h = 3.0, 1.5
    positions, triangles = [], []
    for j in range(FLAG_ROWS + 1):
        for i in range(FLAG_COLUMNS + 1):
            positions.append((w * i / FLAG_COLUMNS - w / 2, h * j / FLAG_ROWS - h / 2, 0.0))
    for j in range(FLAG_ROWS):
        for i in range(FLAG_COLUMNS):
            a = j * (FLAG_COLUMNS + 1) + i
            b, c, d = a + 1, a + FLAG_COLUMNS + 1, a + FLAG_COLUMNS + 2
            triangles += [[a, b, d], [a, d, c]]
    keys = 6
    times = [DURATION * k / keys for k in range(keys + 1)]
    frames, normals = [], []
    for k in range(keys + 1):
        phase = 2 * math.pi * k / keys
        # z = a(x) sin(2.5 x + phase), a(x) = 0.25 (x + w/2) / w; the normal is (-dz/dx, 0, 1).
        frames.append([vec((x, y, 0.25 * (x + w / 2) / w * math.sin(2.5 * x + phase)))
                       for (x, y, _) in positions])
        slope = [0.25 / w * math.sin(2.5 * x + phase) +
                 0.25 * (x + w / 2) / w * 2.5 * math.cos(2.5 * x + phase) for (x, _, _) in positions]
        normals.append([vec((-d / math.hypot(d, 1), 0.0, 1 / math.hypot(d, 1))) for d in slope])
    return {"name": "flag", "kinematics": "free", "transform": {"translation": [0, 2.6, -5.6]},
            "mesh": {"inline": {"positions": frames[0], "normals": normals[0],
                                "triangles": triangles}},
            "material": {"base_color": [0.2, 0.45, 0.85]},
            "animation": {"vertices": track(times, frames), "normals": track(times, normals)}}


def swarm():
    """Triangles on a ball that scatter through the room and gather again (BART's museum)."""
    rng = random.Random(SEED)
    centre = (0.0, 1.4, 0.0)
    gathered, scattered, triangles = [], [], []
    for t in range(SWARM_TRIANGLES):
        # A point on the ball (Fibonacci spiral) and a random spot in the room.
        z = 1 - 2 * (t + 0.5) / SWARM_TRIANGLES
        phi = t * math.pi * (3 - math.sqrt(5))
        s = math.sqrt(1 - z * z)
        on_ball = (0.6 * s * math.cos(phi), 0.6 * z, 0.6 * s * math.sin(phi))
        far = (rng.uniform(-5, 5), rng.uniform(-1.2, 2.2), rng.uniform(-5, 5))
        size = 0.09
        for corner in ((size, 0, 0), (-size / 2, size, 0), (-size / 2, -size / 2, size)):
            gathered.append(vec(tuple(o + c for o, c in zip(on_ball, corner))))
            scattered.append(vec(tuple(o + c for o, c in zip(far, corner))))
        triangles.append([3 * t, 3 * t + 1, 3 * t + 2])
    times = [0.0, DURATION / 2, DURATION]
    return {"name": "swarm", "kinematics": "free", "transform": {"translation": list(centre)},
            "mesh": {"inline": {"positions": gathered, "triangles": triangles}},
            "material": {"base_color": [0.95, 0.7, 0.2], "reflectivity": 0.2},
            "animation": {"vertices": track(times, [gathered, scattered, gathered])}}


def scene():
    keys = 4
    path = [{"time": r4(DURATION * k / keys),
             "position": vec([9 * math.sin(0.5 * math.sin(2 * math.pi * k / keys)), 5.5,
                              9 * math.cos(0.5 * math.sin(2 * math.pi * k / keys))]),
             "look_at": [0, 1, 0]} for k in range(keys + 1)]
    entities = [
        {"name": "camera",
         "camera": {"position": path[0]["position"], "look_at": [0, 1, 0], "vertical_fov_deg": 50},
         "camera_path": {"keys": path}},
        {"name": "light", "transform": {"translation": [1, 3.8, 2]},
         "light": {"type": "point", "intensity": 40}},
    ]
    entities += static_room() + car() + [flag(), swarm()]
    return {"format": "specula-scene", "version": 1,
            "settings": {"width": 512, "height": 400, "max_depth": 2,
                         "background": [0.3, 0.4, 0.55]},
            "entities": entities}


def dump(value, indent=0):
    """JSON with short arrays on one line and long ones wrapped at LINE_WIDTH."""
    pad = " " * indent
    if isinstance(value, dict):
        inner = [f'{pad}  {json.dumps(k)}: {dump(v, indent + 2)}' for k, v in value.items()]
        return "{\n" + ",\n".join(inner) + "\n" + pad + "}"
    if isinstance(value, list) and any(isinstance(v, dict) for v in value):
        inner = [pad + "  " + dump(v, indent + 2) for v in value]
        return "[\n" + ",\n".join(inner) + "\n" + pad + "]"
    if isinstance(value, list):
        text = json.dumps(value, separators=(", ", ": "))
        if len(text) + indent < LINE_WIDTH:
            return text
        items = [json.dumps(v, separators=(",", ":")) for v in value]
        lines, line = [], ""
        for item in items:
            if line and len(line) + len(item) + indent + 4 > LINE_WIDTH:
                lines.append(line)
                line = ""
            line += item + ", "
        lines.append(line)
        body = ("\n" + pad + "  ").join(l.rstrip() for l in lines).rstrip(",")
        return "[\n" + pad + "  " + body + "\n" + pad + "]"
    return json.dumps(value)


def main():
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), OUT)
    with open(path, "w", encoding="utf-8") as f:
        f.write(dump(scene()) + "\n")
    print("wrote", path)


if __name__ == "__main__":
    main()

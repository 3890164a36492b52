#!/usr/bin/env python3
"""Writes samples/scenes/mirror_spheres_{0,1,2,4,8,16,32}.json and three variants of _32.

The test scenes of Ruff, Clua and Fernandes, "Ray-caching textures" (2013), Fig. 5 and Table I:
one reflective sphere facing the camera and N more reflective spheres placed behind the camera,
so that they are visible only through the front sphere's reflection. As in the paper, only the
front sphere carries a ray-cache cube; the hidden spheres are traced conventionally.

Layout (all in metres, +Y up, the camera looks down -Z):
  * the front ("mirror") sphere, radius 1, rests on the ground at the origin;
  * the camera sits at z = 6, slightly above the sphere's centre, looking at it (30 deg fov);
  * hidden spheres (radius 0.75) sit on a shell of radius 10 around the front sphere's centre, in
    4 rows (elevation 0, 11, 22, 33 deg) of 8 columns (azimuth -38.5 .. +38.5 deg in 11 deg
    steps), all behind the camera: large and near enough to fill a good part of the reflection; a scene with N hidden spheres takes the N slots nearest the middle of the
    grid, so the sets are nested (the 4 of mirror_spheres_4 are among the 8 of mirror_spheres_8).
tests/scene/test_json_scene.cpp checks that every hidden sphere lies outside the camera frustum,
that the front sphere lies inside it, and that no two spheres (or a sphere and the camera) meet.

Variants of mirror_spheres_32 for the ray-cache report (bench/cache_sections.cpp, section
`cache`; tests/scene/test_json_scene.cpp checks only the mirror_spheres_N files):
  * mirror_spheres_glass_32: the front sphere is glass (transmission 0.9, ior 1.5, reflectivity
    0.05), so its cube caches both the reflection off its outside and the refraction leaving it;
  * mirror_spheres_heavy_32: the hidden spheres tessellated with 180 segments x 90 rings (32,040
    triangles each; about 1.03 M triangles in all), the same layout otherwise;
  * mirror_spheres_distant_32: the surroundings at least 20 front-sphere radii away: the ground
    20 below the front sphere's centre and the 32 hidden spheres (radius 2) on a shell of radius
    24 around it, where direction-only lookups (the paper's) should be nearly exact; the light is
    moved out and brightened so that the distant surroundings are lit about as before.
  * mirror_spheres_hall_32: the distant layout closed in a hall (walls, floor and ceiling at least
    20 front-sphere radii from its centre; red and green side walls) lit only by an emissive
    panel in the ceiling, with no background: what the front sphere reflects is lit indirectly,
    so in path mode every ray leaving it starts a whole, noisy diffuse path (the ray-cache
    report's path-mode scene, bench/path_sections.cpp).

Python 3 standard library only. Run from anywhere:  python3 samples/scenes/make_mirror_spheres.py
"""

import argparse
import colorsys
import math
import os

COUNTS = [0, 1, 2, 4, 8, 16, 32]
LINE_WIDTH = 100

FRONT_CENTER = (0.0, 1.0, 0.0)
FRONT_RADIUS = 1.0
CAMERA_POSITION = (0.0, 1.6, 6.0)
SHELL_RADIUS = 10.0
HIDDEN_RADIUS = 0.75
ROWS, COLUMNS = 4, 8
ELEVATION_STEP_DEG = 11.0
AZIMUTH_STEP_DEG = 11.0
VARIANTS = ["glass", "heavy", "distant", "hall"]  # of mirror_spheres_32
DISTANT_SHELL_RADIUS = 24.0
DISTANT_HIDDEN_RADIUS = 2.0
DISTANT_GROUND_DEPTH = 20.0
# The hall (x from -30 to 30, y from -19 to 25, z from -30 to 32: every wall at least 20 front-sphere
# radii from its centre, and the hidden-sphere shell, 24 around it, inside) and its ceiling panel.
HALL_HALF_WIDTH = 30.0
HALL_FLOOR, HALL_CEILING = -19.0, 25.0
HALL_BACK, HALL_FRONT = -30.0, 32.0
HALL_PANEL = [16, 16]
HALL_EMISSION = [25, 23.5, 21]


def rounded(v, digits=4):
    """Short decimals keep the files readable; the loader reads them exactly as written."""
    r = round(v, digits)
    return 0.0 if r == 0 else r


def slots(shell_radius=SHELL_RADIUS):
    """All hidden-sphere slots as (row, column, centre), nearest the grid's middle first."""
    out = []
    for row in range(ROWS):
        elevation = math.radians(row * ELEVATION_STEP_DEG)
        for col in range(COLUMNS):
            azimuth = math.radians((col - (COLUMNS - 1) / 2) * AZIMUTH_STEP_DEG)
            center = (
                FRONT_CENTER[0] + shell_radius * math.sin(azimuth) * math.cos(elevation),
                FRONT_CENTER[1] + shell_radius * math.sin(elevation),
                FRONT_CENTER[2] + shell_radius * math.cos(azimuth) * math.cos(elevation),
            )
            middle_distance = abs(col - (COLUMNS - 1) / 2) + abs(row - (ROWS - 1) / 2)
            out.append((middle_distance, row, col, tuple(rounded(c) for c in center)))
    out.sort()
    return [(row, col, center) for _, row, col, center in out]


def hidden_color(row, col):
    """A distinct hue per slot, so each hidden sphere can be told apart in the reflection."""
    hue = ((row * COLUMNS + col) * 0.381966) % 1.0  # golden-ratio steps spread the hues
    return [rounded(c, 3) for c in colorsys.hsv_to_rgb(hue, 0.65, 0.85)]


def hall():
    """The hall of mirror_spheres_hall_32: five walls and a floor, facing inwards, and the
    ceiling's light panel."""
    x, y0, y1, z0, z1 = HALL_HALF_WIDTH, HALL_FLOOR, HALL_CEILING, HALL_BACK, HALL_FRONT
    height, depth_ = y1 - y0, z1 - z0
    mid_y, mid_z = rounded((y0 + y1) / 2), rounded((z0 + z1) / 2)
    grey, floor = [0.7, 0.7, 0.7], [0.55, 0.55, 0.5]
    half_turn = 0.70710678

    def plane(name, translation, rotation, size, color):
        return {"name": name, "transform": {"translation": translation, "rotation": rotation},
                "mesh": {"primitive": "plane", "size": size}, "material": {"base_color": color}}

    return [
        plane("floor", [0, y0, mid_z], [0, 0, 0, 1], [2 * x, depth_], floor),
        plane("ceiling", [0, y1, mid_z], [1, 0, 0, 0], [2 * x, depth_], grey),
        plane("back wall", [0, mid_y, z0], [half_turn, 0, 0, half_turn], [2 * x, height], grey),
        plane("front wall", [0, mid_y, z1], [-half_turn, 0, 0, half_turn], [2 * x, height],
              grey),
        plane("left wall (red)", [-x, mid_y, mid_z], [0, 0, -half_turn, half_turn],
              [height, depth_], [0.63, 0.065, 0.05]),
        plane("right wall (green)", [x, mid_y, mid_z], [0, 0, half_turn, half_turn],
              [height, depth_], [0.14, 0.45, 0.091]),
        {
            "name": "light panel",
            "transform": {"translation": [0, rounded(y1 - 0.05), 0], "rotation": [1, 0, 0, 0]},
            "mesh": {"primitive": "plane", "size": HALL_PANEL},
            "material": {"base_color": [0, 0, 0], "emission": HALL_EMISSION},
        },
    ]


def scene(count, cache_resolution, variant=None):
    """The scene with `count` hidden spheres; variant None (the paper's), "glass", "heavy",
    "distant" or "hall" (see the module docstring)."""
    front_material = {"base_color": [0.9, 0.9, 0.9], "reflectivity": 0.9}
    if variant == "glass":
        front_material = {"base_color": [0.9, 0.9, 0.9], "reflectivity": 0.05,
                          "transmission": 0.9, "ior": 1.5}
    shell_radius, hidden_radius = SHELL_RADIUS, HIDDEN_RADIUS
    hidden_segments, hidden_rings = 32, 16
    light = {"translation": [3, 10, 4]}, 150
    ground = {"mesh": {"primitive": "plane", "size": 60}}
    if variant == "heavy":
        hidden_segments, hidden_rings = 180, 90
    if variant in ("distant", "hall"):
        shell_radius, hidden_radius = DISTANT_SHELL_RADIUS, DISTANT_HIDDEN_RADIUS
        light = {"translation": [20, 40, 30]}, 4000
        ground = {
            "transform": {"translation": [0, rounded(FRONT_CENTER[1] - DISTANT_GROUND_DEPTH), 0]},
            "mesh": {"primitive": "plane", "size": 400},
        }
    entities = [
        {
            "name": "camera",
            "camera": {
                "position": list(CAMERA_POSITION),
                "look_at": list(FRONT_CENTER),
                "vertical_fov_deg": 30,
            },
        },
    ]
    if variant == "hall":
        entities += hall()
    else:
        entities += [
            {
                "name": "light",
                "transform": light[0],
                "light": {"type": "point", "color": [1, 1, 1], "intensity": light[1]},
            },
            dict({"name": "ground"}, **ground, material={"base_color": [0.55, 0.55, 0.5]}),
        ]
    entities += [
        {
            "name": "glass sphere" if variant == "glass" else "mirror sphere",
            "transform": {"translation": list(FRONT_CENTER)},
            "mesh": {"primitive": "sphere", "radius": FRONT_RADIUS, "segments": 64, "rings": 32},
            "material": front_material,
            "ray_cache": {"resolution": cache_resolution},
        },
    ]
    for i, (row, col, center) in enumerate(slots(shell_radius)[:count]):
        entities.append(
            {
                "name": "hidden sphere %d" % i,
                "transform": {"translation": list(center)},
                "mesh": {"primitive": "sphere", "radius": hidden_radius,
                         "segments": hidden_segments, "rings": hidden_rings},
                "material": {"base_color": hidden_color(row, col), "reflectivity": 0.5},
            }
        )
    return {
        "format": "specula-scene",
        "version": 1,
        "settings": {"width": 1024, "height": 1024, "max_depth": 5,
                     "background": [0, 0, 0] if variant == "hall" else [0.3, 0.4, 0.55]},
        "entities": entities,
    }


def scalar(v):
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return repr(v)


def depth(v):
    """Nesting depth: 0 for a scalar, 1 for a container of scalars, and so on."""
    if isinstance(v, dict):
        return 1 + max((depth(x) for x in v.values()), default=0)
    if isinstance(v, list):
        return 1 + max((depth(x) for x in v), default=0)
    return 0


def one_line(v):
    if isinstance(v, dict):
        return "{" + ", ".join(scalar(k) + ": " + one_line(x) for k, x in v.items()) + "}"
    if isinstance(v, list):
        return "[" + ", ".join(one_line(x) for x in v) + "]"
    return scalar(v)


def dump(v, indent=0, column=0):
    """JSON in the layout of Specula's writer: values nested at most two deep stay on one line
    when they fit in LINE_WIDTH columns (`column` is where v starts on its line)."""
    if not isinstance(v, (dict, list)) or not v:
        return one_line(v)
    if depth(v) <= 2 and column + len(one_line(v)) <= LINE_WIDTH:
        return one_line(v)
    items = list(v.items()) if isinstance(v, dict) else [(None, x) for x in v]
    open_, close = ("{", "}") if isinstance(v, dict) else ("[", "]")
    lines = []
    for k, x in items:
        key = "" if k is None else scalar(k) + ": "
        lines.append(" " * (indent + 2) + key + dump(x, indent + 2, indent + 2 + len(key)))
    return open_ + "\n" + ",\n".join(lines) + "\n" + " " * indent + close


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default=os.path.dirname(os.path.abspath(__file__)),
                        help="output folder (default: this script's folder)")
    parser.add_argument("--cache-resolution", type=int, default=128,
                        help="ray-cache cube face resolution of the front sphere (power of two)")
    args = parser.parse_args()
    for count in COUNTS:
        path = os.path.join(args.out, "mirror_spheres_%d.json" % count)
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(dump(scene(count, args.cache_resolution)) + "\n")
        print(path)
    for variant in VARIANTS:
        path = os.path.join(args.out, "mirror_spheres_%s_32.json" % variant)
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(dump(scene(32, args.cache_resolution, variant)) + "\n")
        print(path)


if __name__ == "__main__":
    main()

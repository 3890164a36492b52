#!/usr/bin/env python3
"""Writes the binary mesh test files of this folder (run from anywhere; output is deterministic).

Binary files are generated rather than hand-edited so their content can be read here:
  cube_binary.ply       unit cube [0,1]^3, 8 vertices, 12 triangles, little-endian
  cube_binary.stl       unit cube [0,1]^3, 12 facets (36 corners, 8 distinct positions)
  cube_binary.off       unit cube [0,1]^3, 8 vertices, 6 quads ("OFF BINARY", little-endian
                        32-bit counts, floats and indices: the layout OpenMesh writes)
  truncated_binary.stl  header claims 12 facets, the file holds 5
  absurd_count_binary.off  binary OFF claiming 2^31 - 1 vertices in 100 bytes
  binary_garbage.stl    300 pseudo-random bytes (neither ASCII nor size-consistent binary STL)
  out_of_range_index_binary.ply  binary triangle referring to vertex 7 of 3
  negative_list_length.ply       binary face whose "int" corner count is -5 (OpenMesh loops)
  end_header_whitespace.ply      binary cube triangle with spaces before "end_header"
  nan_vertex_binary.stl          binary cube whose facet 3 has a NaN corner coordinate
"""
import os
import struct

HERE = os.path.dirname(os.path.abspath(__file__))

CUBE_POSITIONS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0),
                  (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
# The quads of cube.obj (0-based), outward counter-clockwise, each split into two triangles.
CUBE_QUADS = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (3, 7, 6, 2), (0, 4, 7, 3), (1, 2, 6, 5)]
CUBE_TRIANGLES = [t for a, b, c, d in CUBE_QUADS for t in ((a, b, c), (a, c, d))]


def write(name, data):
    with open(os.path.join(HERE, name), "wb") as f:
        f.write(data)


def ply_cube():
    header = ("ply\nformat binary_little_endian 1.0\n"
              "comment unit cube [0,1]^3, 8 vertices, 12 triangles\n"
              "element vertex 8\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 12\nproperty list uchar int vertex_indices\nend_header\n")
    body = b"".join(struct.pack("<3f", *p) for p in CUBE_POSITIONS)
    body += b"".join(struct.pack("<B3i", 3, *t) for t in CUBE_TRIANGLES)
    return header.encode("ascii") + body


def ply_triangle(count_type="uchar", count=3, indices=(0, 1, 2), before_end=""):
    header = ("ply\nformat binary_little_endian 1.0\n"
              "element vertex 3\nproperty float x\nproperty float y\nproperty float z\n"
              "element face 1\nproperty list %s int vertex_indices%s\nend_header\n"
              % (count_type, before_end))
    body = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    body += struct.pack("<B" if count_type == "uchar" else "<i", count)
    body += struct.pack("<3i", *indices)
    return header.encode("ascii") + body


def off_cube(vertex_count=len(CUBE_POSITIONS)):
    body = struct.pack("<3i", vertex_count, len(CUBE_QUADS), 0)
    body += b"".join(struct.pack("<3f", *p) for p in CUBE_POSITIONS)
    body += b"".join(struct.pack("<5i", 4, *q) for q in CUBE_QUADS)
    return b"OFF BINARY\n" + body


def stl_facet(t):
    ps = [CUBE_POSITIONS[i] for i in t]
    u = [ps[1][k] - ps[0][k] for k in range(3)]
    v = [ps[2][k] - ps[0][k] for k in range(3)]
    n = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
    return struct.pack("<3f", *n) + b"".join(struct.pack("<3f", *p) for p in ps) + b"\0\0"


def stl_binary(facets, claimed, nan_facet=None):
    header = b"binary cube".ljust(80, b"\0")
    body = [stl_facet(t) for t in facets]
    if nan_facet is not None:  # first corner's x (after the 12-byte facet normal)
        f = body[nan_facet]
        body[nan_facet] = f[:12] + struct.pack("<f", float("nan")) + f[16:]
    return header + struct.pack("<I", claimed) + b"".join(body)


def garbage(n, seed=12345):
    out = bytearray()
    x = seed
    for _ in range(n):
        x = (1103515245 * x + 12345) % 2**31  # glibc-style LCG: fixed bytes, no randomness
        out.append((x >> 16) & 0xFF)
    return bytes(out)


write("cube_binary.ply", ply_cube())
write("out_of_range_index_binary.ply", ply_triangle(indices=(0, 1, 7)))
write("negative_list_length.ply", ply_triangle(count_type="int", count=-5))
write("end_header_whitespace.ply", ply_triangle(before_end="   "))
write("cube_binary.off", off_cube())
write("absurd_count_binary.off", off_cube(vertex_count=2**31 - 1)[:100])
write("cube_binary.stl", stl_binary(CUBE_TRIANGLES, len(CUBE_TRIANGLES)))
write("nan_vertex_binary.stl", stl_binary(CUBE_TRIANGLES, len(CUBE_TRIANGLES), nan_facet=3))
write("truncated_binary.stl", stl_binary(CUBE_TRIANGLES[:5], len(CUBE_TRIANGLES)))
g = garbage(300)
assert not g.lstrip().lower().startswith(b"solid")
write("binary_garbage.stl", g)

// Numerical stability on hard cases, for every backend of the build (Embree too, for comparison):
//   - leaks: rays aimed exactly at the shared vertices and edge midpoints of closed meshes (an
//     icosphere, a box whose faces share positions but not indices) and at the interior edges of
//     the Stanford bunny, with the geometry at the origin, translated to 1e4, 1e5 and 1e6, and
//     scaled by 1e-4 and 1e4, static (baked in world space) and as a moving instance;
//   - acne: rays reflected off hit points of convex meshes, from origins offset by
//     offset_ray_origin, must never hit their own object again;
//   - grazing: rays skimming a box's faces at shallow angles must hit it;
//   - degenerate triangles: zero-area and needle triangles among ordinary ones never produce a hit
//     on a zero-area triangle, a non-finite distance, or a miss of a neighbour;
//   - invalid rays (NaN or infinite components, zero direction, empty intervals): a clean miss.
// Watertight backends (BackendInfo::watertight) must show 0 leaks everywhere; the others are
// measured and reported. With SPECULA_ROBUSTNESS_TABLE=FILE the counts are also written there as
// the Markdown table docs/design/robustness.md reproduces.

#include "scene_builder.h"
#include "specula/geometry/ray_offset.h"
#include "specula/scene/mesh_io.h"

#include <glm/gtx/component_wise.hpp>

#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

namespace specula {
namespace {

bool watertight(const std::string& backend) { return backend_info(backend).watertight; }


struct Shape {
  std::string name;
  std::shared_ptr<const TriangleMesh> mesh;
  bool closed;   ///< aim from inside at every vertex and edge (else: interior edges from outside)
  float radius;  ///< of the unscaled mesh around its centre
  vec3 centre;   ///< of the unscaled mesh
};

std::vector<Shape> shapes() {
  std::vector<Shape> list;
  list.push_back({"icosphere", std::make_shared<const TriangleMesh>(test::icosphere(4)), true, 1.0f, vec3(0)});
  list.push_back({"box", std::make_shared<const TriangleMesh>(make_primitive(test::primitive("box", 1.0f, vec3(2.0f, 1.0f, 1.5f)), "test")),
                  true, 1.0f, vec3(0)});
  TriangleMesh bunny = load_mesh_file(std::filesystem::path(SPECULA_SOURCE_DIR) / "samples/models/bunny.obj");
  Aabb b;
  for (const vec3& p : bunny.positions) b.grow(p);
  list.push_back({"bunny", std::make_shared<const TriangleMesh>(std::move(bunny)), false,
                  0.5f * glm::length(b.extent()), b.center()});
  return list;
}

struct Placement {
  std::string name;
  vec3 translation;
  float scale;
  Kinematics::Type kinematics;
};

std::vector<Placement> placements() {
  return {{"origin", vec3(0), 1.0f, Kinematics::Type::Static},
          {"at 1e4", vec3(1e4f, -1e4f, 1e4f), 1.0f, Kinematics::Type::Static},
          {"at 1e5", vec3(1e5f, 1e5f, -1e5f), 1.0f, Kinematics::Type::Static},
          {"at 1e6", vec3(-1e6f, 1e6f, 1e6f), 1.0f, Kinematics::Type::Static},
          {"scaled 1e-4", vec3(0.3f, -0.2f, 0.1f), 1e-4f, Kinematics::Type::Static},
          {"scaled 1e4", vec3(0), 1e4f, Kinematics::Type::Static},
          {"instance at 1e5", vec3(1e5f, 0, -1e5f), 1.0f, Kinematics::Type::Free},
          {"instance scaled 1e-4", vec3(0.3f, -0.2f, 0.1f), 1e-4f, Kinematics::Type::Free}};
}

struct Count {
  long long bad = 0, shot = 0;
};

/// The table: rows "case", columns backends.
std::map<std::string, std::map<std::string, Count>>& table() {
  static std::map<std::string, std::map<std::string, Count>> t;
  return t;
}

class Robustness : public ::testing::TestWithParam<std::string> {
protected:
  [[nodiscard]] const std::string& backend() const { return GetParam(); }
  static void TearDownTestSuite() {
    const char* path = std::getenv("SPECULA_ROBUSTNESS_TABLE");
    if (path == nullptr || *path == '\0') return;
    std::set<std::string> columns;
    for (const auto& [row, cells] : table())
      for (const auto& [b, c] : cells) columns.insert(b);
    std::ofstream out(path);
    out << "| case |";
    for (const std::string& c : columns) out << " " << c << " |";
    out << "\n|---|";
    for (std::size_t i = 0; i < columns.size(); ++i) out << "---:|";
    out << "\n";
    for (const auto& [row, cells] : table()) {
      out << "| " << row << " |";
      for (const std::string& c : columns) {
        const auto it = cells.find(c);
        if (it == cells.end())
          out << " – |";
        else
          out << " " << it->second.bad << " / " << it->second.shot << " |";
      }
      out << "\n";
    }
  }
  void record(const std::string& row, const Count& c) { table()[row][backend()] = c; }
};

TEST_P(Robustness, RaysAtSharedEdgesAndVerticesNeverLeak) {
  for (const Shape& shape : shapes()) {
    for (const Placement& place : placements()) {
      ecs::Registry reg;
      const ecs::Entity e = reg.create();
      // Centre the shape on the placement's translation.
      const Transform tr = test::at(place.translation - place.scale * shape.centre, vec3(place.scale));
      reg.emplace<Transform>(e, tr);
      reg.emplace<Mesh>(e, Mesh{shape.mesh, {}, {}, 0});
      reg.emplace<Kinematics>(e, Kinematics{place.kinematics});
      const test::TracedWorld world(reg, backend());
      const mat4 m = tr.parent_from_local();
      const vec3 centre = place.translation;
      const float radius = shape.radius * place.scale;
      const TriangleMesh& mesh = *shape.mesh;
      // Interior edges (two triangles) and the vertices all of whose edges are interior, by
      // position: the box's faces share positions, not indices.
      std::map<std::tuple<float, float, float>, std::uint32_t> weld;
      std::vector<std::uint32_t> id(mesh.positions.size());
      for (std::size_t v = 0; v < mesh.positions.size(); ++v) {
        const vec3& p = mesh.positions[v];
        id[v] = weld.try_emplace({p.x, p.y, p.z}, std::uint32_t(v)).first->second;
      }
      // Per welded vertex and edge, the triangles around it (a target is shot at only if every
      // one of them faces the origin the same way, so the ray crosses the surface there rather
      // than grazing a silhouette, where it may rightly slip past).
      std::map<std::pair<std::uint32_t, std::uint32_t>, std::vector<std::uint32_t>> edge_tris;
      std::map<std::uint32_t, std::vector<std::uint32_t>> vertex_tris;
      for (std::uint32_t t = 0; t < mesh.triangles.size(); ++t) {
        const uvec3& tri = mesh.triangles[t];
        for (int k = 0; k < 3; ++k) {
          edge_tris[std::minmax(id[tri[k]], id[tri[(k + 1) % 3]])].push_back(t);
          vertex_tris[id[tri[k]]].push_back(t);
        }
      }
      std::vector<bool> boundary_vertex(mesh.positions.size(), false);
      for (const auto& [edge, tris] : edge_tris)
        if (tris.size() != 2) boundary_vertex[edge.first] = boundary_vertex[edge.second] = true;
      // Static placements are traced as the layer bakes them, in world space (rounded there: at
      // 1e6 a bunny 0.15 across collapses onto a few float positions); instances in object space.
      const bool baked = place.kinematics == Kinematics::Type::Static;
      std::vector<vec3> P = mesh.positions;
      if (baked) {
        // The layer's own world-space vertices (recomputing them could round differently).
        const SceneTables& tables = world.tables();
        const gpu::GpuMesh& gm = tables.meshes[tables.instances[tables.static_instances.at(0)].mesh];
        ASSERT_EQ(gm.vertex_count, P.size());
        P.assign(tables.positions.begin() + gm.first_vertex,
                 tables.positions.begin() + gm.first_vertex + gm.vertex_count);
      }
      struct Target {
        vec3 p; // in the space of P
        const std::vector<std::uint32_t>* around;
      };
      std::vector<Target> targets;
      for (const auto& [v, tris] : vertex_tris)
        if (!boundary_vertex[v]) targets.push_back({P[v], &tris});
      for (const auto& [edge, tris] : edge_tris)
        if (tris.size() == 2) targets.push_back({0.5f * (P[edge.first] + P[edge.second]), &tris});
      const auto crosses = [&](const Target& target, const vec3& origin_local) {
        int sign = 0;
        for (const std::uint32_t t : *target.around) {
          const uvec3& tri = mesh.triangles[t];
          const vec3 n = glm::cross(P[tri.y] - P[tri.x], P[tri.z] - P[tri.x]);
          if (!(glm::length(n) > 0.0f)) return false; // collapsed by rounding
          if (baked) {
            // Folded by rounding (its normal turned by more than ~6°): no longer the surface the
            // edge test is about.
            const vec3 n0 = glm::cross(mesh.positions[tri.y] - mesh.positions[tri.x],
                                       mesh.positions[tri.z] - mesh.positions[tri.x]);
            if (glm::dot(glm::normalize(n), glm::normalize(n0)) < 0.995f) return false;
          }
          const float c = glm::dot(glm::normalize(n), glm::normalize(origin_local - target.p));
          if (std::abs(c) < 0.05f) return false;
          const int side = c > 0.0f ? 1 : -1;
          if (sign != 0 && side != sign) return false;
          sign = side;
        }
        return true;
      };
      const std::vector<vec3> origins =
          shape.closed ? std::vector<vec3>{centre, centre + radius * vec3(0.13f, -0.21f, 0.07f)}
                       : std::vector<vec3>{centre + radius * vec3(2.1f, 1.3f, 2.7f),
                                           centre + radius * vec3(-2.5f, 0.4f, -1.9f)};
      const mat4 local_from_world = baked ? mat4(1.0f) : glm::inverse(m);
      const mat4 world_from_local = baked ? mat4(1.0f) : m;
      std::vector<Ray> rays;
      for (const vec3& origin : origins) {
        const vec3 origin_local = vec3(local_from_world * vec4(origin, 1.0f));
        for (const Target& target_local : targets) {
          if (!crosses(target_local, origin_local)) continue;
          const vec3 target = vec3(world_from_local * vec4(target_local.p, 1.0f));
          Ray ray;
          ray.origin = origin;
          ray.direction = glm::normalize(target - origin);
          rays.push_back(ray);
        }
      }
      // One batch: a device backend pays its submission once, not per ray.
      std::vector<Hit> hits(rays.size());
      world.tracer->intersect(rays, hits);
      Count count;
      count.shot = static_cast<long long>(rays.size());
      for (const Hit& hit : hits) count.bad += hit.hit() ? 0 : 1;
      const std::string row = "leaks: " + shape.name + " " + place.name;
      record(row, count);
      ASSERT_GE(count.shot, 50) << row; // the 12-triangle box: 8 vertices, 18 edges, 2 origins
      // A mesh whose triangles are only a few float steps across at its position (the bunny's,
      // about 0.15, at 1e6 where floats are 0.0625 apart) is rounded into a crumpled,
      // self-overlapping surface: its counts go into the table, but "a shared edge" no longer
      // means what the test is about.
      const float ulp = std::nextafter(glm::compMax(glm::abs(place.translation)) + radius,
                                       std::numeric_limits<float>::infinity()) -
                        (glm::compMax(glm::abs(place.translation)) + radius);
      double edge_sum = 0.0;
      for (const uvec3& t : mesh.triangles)
        edge_sum += double(glm::length(mesh.positions[t.y] - mesh.positions[t.x]));
      const float mean_edge = float(edge_sum / double(mesh.triangles.size())) * place.scale;
      const bool resolved = !baked || mean_edge / ulp >= 8.0f;
      if (watertight(backend()) && resolved) {
        EXPECT_EQ(count.bad, 0) << row << ": " << count.bad << " of " << count.shot;
      }
    }
  }
}

TEST_P(Robustness, ReflectedRaysNeverHitTheirOwnConvexSurface) {
  // Static placements: the layer bakes the mesh, so the hit triangle is read in world space.
  // The convex shapes only (shapes() is built once: it reads the bunny from disk).
  const std::vector<Shape> all = shapes();
  const std::vector<Shape> convex(all.begin(), all.begin() + 2); // icosphere, box
  for (const Placement& place : placements()) {
    if (place.kinematics != Kinematics::Type::Static) continue;
    for (const Shape& shape : convex) {
      ecs::Registry reg;
      const ecs::Entity e = reg.create();
      reg.emplace<Transform>(e, test::at(place.translation, vec3(place.scale)));
      reg.emplace<Mesh>(e, Mesh{shape.mesh, {}, {}, 0});
      reg.emplace<Kinematics>(e, Kinematics{place.kinematics});
      const test::TracedWorld world(reg, backend());
      const SceneTables& tables = world.tables();
      std::mt19937 rng(11);
      std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
      // Both generations of rays go through in batches (a device backend pays its submission once).
      std::vector<Ray> ins(4000);
      for (Ray& in : ins) {
        vec3 d(0.0f);
        while (glm::length(d) < 0.1f) d = vec3(unit(rng), unit(rng), unit(rng));
        in.origin = place.translation + glm::normalize(d) * (4.0f * place.scale);
        in.direction = glm::normalize(place.translation + 0.3f * place.scale * vec3(unit(rng), unit(rng), unit(rng)) - in.origin);
      }
      std::vector<Hit> in_hits(ins.size());
      world.tracer->intersect(ins, in_hits);
      std::vector<Ray> outs;
      for (std::size_t i = 0; i < ins.size(); ++i) {
        const Ray& in = ins[i];
        const Hit& hit = in_hits[i];
        if (!hit.hit()) continue;
        const gpu::GpuMesh& gm = tables.meshes[tables.instances[hit.instance].mesh];
        const uvec3 tri = tables.triangles[gm.first_triangle + hit.primitive];
        const vec3& a = tables.positions[gm.first_vertex + tri.x];
        const vec3& b = tables.positions[gm.first_vertex + tri.y];
        const vec3& c = tables.positions[gm.first_vertex + tri.z];
        const float w = 1.0f - hit.uv.x - hit.uv.y;
        const vec3 p = w * a + hit.uv.x * b + hit.uv.y * c;
        vec3 n = glm::normalize(glm::cross(b - a, c - a));
        if (glm::dot(n, in.direction) > 0.0f) n = -n;
        Ray out;
        out.origin = offset_ray_origin(p, barycentric_error(a, b, c, w, hit.uv.x, hit.uv.y), n);
        out.direction = glm::normalize(in.direction - 2.0f * glm::dot(in.direction, n) * n);
        outs.push_back(out);
      }
      std::vector<Hit> out_hits(outs.size());
      std::vector<std::uint8_t> out_blocked(outs.size());
      world.tracer->intersect(outs, out_hits);
      world.tracer->occluded(outs, out_blocked);
      Count count;
      count.shot = static_cast<long long>(outs.size());
      for (std::size_t i = 0; i < outs.size(); ++i)
        count.bad += out_hits[i].hit() || out_blocked[i] != 0 ? 1 : 0;
      const std::string row = "acne: " + shape.name + " " + place.name;
      record(row, count);
      ASSERT_GT(count.shot, 1000) << row;
      EXPECT_EQ(count.bad, 0) << row;
    }
  }
}

TEST_P(Robustness, GrazingRaysAlongABoxsFacesHitIt) {
  for (const Placement& place : placements()) {
    if (place.kinematics != Kinematics::Type::Static) continue;
    ecs::Registry reg;
    test::add_mesh(reg, test::primitive("box", 1.0f, vec3(2.0f)), test::at(place.translation, vec3(place.scale)));
    const test::TracedWorld world(reg, backend());
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> unit(-1.0f, 1.0f);
    Count count;
    const float h = place.scale; // half size
    for (int i = 0; i < 4000; ++i) {
      // A point on the top face (y = +h), well inside it, approached from far away at an angle of
      // 1e-3 to 1e-2 radians above the face's plane.
      const vec3 target = place.translation + vec3(unit(rng) * 0.9f * h, h, unit(rng) * 0.9f * h);
      const float angle = 1e-3f + 9e-3f * (0.5f + 0.5f * unit(rng));
      const float phi = 3.14159265f * unit(rng);
      const vec3 dir = glm::normalize(vec3(std::cos(phi) * std::cos(angle), -std::sin(angle), std::sin(phi) * std::cos(angle)));
      // The ray through the (rounded) origin and the target itself, so that it meets the face
      // in exact arithmetic whatever the coordinates' magnitude.
      Ray ray;
      ray.origin = target - dir * (3.0f * h);
      if (ray.origin.y <= target.y) continue; // rounded onto the face's plane: not grazing
      ray.direction = glm::normalize(target - ray.origin);
      ++count.shot;
      if (!world.intersect(ray).hit()) ++count.bad;
    }
    const std::string row = "grazing: box " + place.name;
    record(row, count);
    if (watertight(backend())) {
      EXPECT_EQ(count.bad, 0) << row;
    }
  }
}

TEST_P(Robustness, DegenerateTrianglesNeverHitAndNeverHideTheirNeighbours) {
  // A strip of ordinary triangles; between each pair a zero-area triangle (three collinear
  // points, or a repeated vertex) and a needle 1e-7 wide.
  auto mesh = std::make_shared<TriangleMesh>();
  std::vector<std::uint32_t> ordinary, zero_area;
  for (int i = 0; i < 200; ++i) {
    const float x = float(i);
    const auto base = std::uint32_t(mesh->positions.size());
    mesh->positions.insert(mesh->positions.end(),
                           {{x, 0, 0}, {x + 1, 0, 0}, {x, 1, 0},            // ordinary
                            {x, 0, 0.5f}, {x + 0.5f, 0.5f, 0.5f}, {x + 1, 1, 0.5f}, // collinear
                            {x + 0.2f, 0.2f, 0.2f}, {x + 0.7f, 0.3f, 0.2f},          // repeated
                            {x, 0.5f, 0.3f}, {x + 1, 0.5f, 0.3f}, {x + 0.5f, 0.5f + 1e-7f, 0.3f}}); // needle
    ordinary.push_back(std::uint32_t(mesh->triangles.size()));
    mesh->triangles.emplace_back(base, base + 1, base + 2);
    zero_area.push_back(std::uint32_t(mesh->triangles.size()));
    mesh->triangles.emplace_back(base + 3, base + 4, base + 5);
    zero_area.push_back(std::uint32_t(mesh->triangles.size()));
    mesh->triangles.emplace_back(base + 6, base + 7, base + 6);
    mesh->triangles.emplace_back(base + 8, base + 9, base + 10);
  }
  mesh->compute_vertex_normals();
  ecs::Registry reg;
  const ecs::Entity e = reg.create();
  reg.emplace<Transform>(e, test::at(vec3(0)));
  reg.emplace<Mesh>(e, Mesh{mesh, {}, {}, 0});
  reg.emplace<Kinematics>(e, Kinematics{Kinematics::Type::Static});
  const test::TracedWorld world(reg, backend());
  const std::set<std::uint32_t> zero(zero_area.begin(), zero_area.end());
  Count count;
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u01(0.05f, 0.4f);
  for (const std::uint32_t t : ordinary) {
    for (int k = 0; k < 10; ++k) {
      // From above, through the degenerate layers, at a point inside the ordinary triangle.
      const uvec3 tri = mesh->triangles[t];
      const float a = u01(rng), b = u01(rng);
      const vec3 p = (1 - a - b) * mesh->positions[tri.x] + a * mesh->positions[tri.y] + b * mesh->positions[tri.z];
      Ray ray;
      ray.origin = p + vec3(0.01f, 0.02f, 2.0f);
      ray.direction = glm::normalize(p - ray.origin);
      const Hit hit = world.intersect(ray);
      ++count.shot;
      const bool bad = !hit.hit() || !std::isfinite(hit.t) || zero.count(hit.primitive) != 0 ||
                       !std::isfinite(hit.uv.x) || !std::isfinite(hit.uv.y);
      count.bad += bad ? 1 : 0;
    }
  }
  // Aimed straight at the zero-area triangles (edge-on and face-on): never a hit on one of them.
  for (const std::uint32_t t : zero_area) {
    const uvec3 tri = mesh->triangles[t];
    const vec3 p = (mesh->positions[tri.x] + mesh->positions[tri.y] + mesh->positions[tri.z]) / 3.0f;
    for (const vec3& from : {p + vec3(0, 0, 3), p + vec3(0.3f, -0.2f, 3), p + vec3(-3, -3, 0)}) {
      Ray ray;
      ray.origin = from;
      ray.direction = glm::normalize(p - from);
      const Hit hit = world.intersect(ray);
      ++count.shot;
      count.bad += (hit.hit() && (zero.count(hit.primitive) != 0 || !std::isfinite(hit.t))) ? 1 : 0;
    }
  }
  record("degenerate: zero-area and needle triangles", count);
  EXPECT_EQ(count.bad, 0);
}

TEST_P(Robustness, InvalidRaysMissCleanly) {
  ecs::Registry reg;
  test::add_mesh(reg, test::primitive("sphere", 1.0f), test::at(vec3(0)));
  test::add_mesh(reg, test::primitive("box", 1.0f), test::at(vec3(3, 0, 0)), Material{}, Kinematics::Type::Free);
  const test::TracedWorld world(reg, backend());
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float inf = std::numeric_limits<float>::infinity();
  std::vector<Ray> rays;
  const auto add = [&](vec3 o, vec3 d, float tnear = 0.0f,
                       float tfar = std::numeric_limits<float>::infinity()) {
    Ray r;
    r.origin = o;
    r.direction = d;
    r.tnear = tnear;
    r.tfar = tfar;
    rays.push_back(r);
  };
  add(vec3(nan, 0, 5), vec3(0, 0, -1));
  add(vec3(0, 0, 5), vec3(0, nan, -1));
  add(vec3(0, 0, 5), vec3(0, 0, -inf));
  add(vec3(inf, 0, 5), vec3(-1, 0, 0));
  add(vec3(0, 0, 5), vec3(0, 0, 0));
  add(vec3(0, 0, 5), vec3(0, 0, -1), nan, inf);
  add(vec3(0, 0, 5), vec3(0, 0, -1), 0.0f, nan);
  add(vec3(0, 0, 5), vec3(0, 0, -1), 6.0f, 2.0f);
  add(vec3(3, 0, 5), vec3(0, 0, -1), inf, inf);
  std::vector<Hit> hits(rays.size());
  std::vector<std::uint8_t> occluded(rays.size(), 7);
  world.tracer->intersect(rays, hits);
  world.tracer->occluded(rays, occluded);
  Count count;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    ++count.shot;
    const bool bad = hits[i].hit() || occluded[i] != 0;
    count.bad += bad ? 1 : 0;
    EXPECT_FALSE(hits[i].hit()) << "ray " << i;
    EXPECT_EQ(occluded[i], 0) << "ray " << i;
  }
  record("invalid rays (NaN, Inf, zero direction, empty interval)", count);
  // The same tracer still answers valid rays afterwards.
  Ray ok;
  ok.origin = vec3(0, 0, 5);
  ok.direction = vec3(0, 0, -1);
  EXPECT_NEAR(world.intersect(ok).t, 4.0f, 1e-3f);
}

INSTANTIATE_TEST_SUITE_P(Backends, Robustness, ::testing::ValuesIn(test::available_backends()),
                         [](const auto& param) { return test::test_name(param.param); });

} // namespace
} // namespace specula

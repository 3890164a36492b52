#include "specula/gpu/gpu_scene.h"

#include "specula/core/assert.h"
#include "specula/core/error.h"
#include "specula/render/scene_layer.h"

#include <algorithm>
#include <bit>
#include <cstring>
#include <string>

namespace specula::gpu {

namespace {

/// Bindings of shaders/shared/gpu_scene_layout.h.
enum Binding : std::uint32_t {
  kPositions = 0,
  kTriangles = 1,
  kMeshes = 2,
  kInstances = 3,
  kHeader = 4,
  kNodes = 5,
  kWords = 6,
  kTraced = 7,
};

NativeOptions native_options(GpuStructure structure, float grid_density) {
  NativeOptions o;
  o.static_structure = structure == GpuStructure::grid ? StaticStructure::grid : StaticStructure::bvh;
  o.wide_bvh = false; // the device traverses the binary tree; this tracer answers as it does
  o.grid_density = grid_density;
  return o;
}

template <class T> void append(std::vector<T>& to, std::span<const T> from) {
  to.insert(to.end(), from.begin(), from.end());
}

/// BVH nodes in binding 5's layout.
void append_nodes(std::vector<GpuNode>& to, std::span<const BvhNode> from) {
  for (const BvhNode& n : from)
    to.push_back({n.bounds_min, n.bounds_max.x, n.bounds_max.y, n.bounds_max.z, n.index, n.count});
}

/// Mesh `mesh`'s triangles as the traversal reads them: each vertex's position (its float bits)
/// and a zero word, one RGBA32UI texel (binding 7 is a texel buffer), three per triangle.
void append_triangles(std::vector<std::uint32_t>& to, const SceneTables& tables, std::uint32_t mesh) {
  const GpuMesh& m = tables.meshes[mesh];
  for (std::uint32_t t = 0; t < m.triangle_count; ++t) {
    const uvec3 tri = tables.triangles[m.first_triangle + t] + uvec3(m.first_vertex);
    for (int k = 0; k < 3; ++k) {
      const vec3& p = tables.positions[tri[k]];
      to.insert(to.end(), {std::bit_cast<std::uint32_t>(p.x), std::bit_cast<std::uint32_t>(p.y),
                           std::bit_cast<std::uint32_t>(p.z), 0u});
    }
  }
}

/// Words of one traced triangle (binding 7).
constexpr std::size_t kTracedWords = 12;

std::uint32_t size32(std::size_t n) { return std::uint32_t(n); }

} // namespace

GpuScene::GpuScene(Context& context, GpuStructure structure, float grid_density)
    : context_(context), structure_(structure), native_(8, native_options(structure, grid_density)) {
  for (std::uint32_t i = 0; i < kSceneBindings; ++i) {
    buffers_[i] = context.make_buffer(16);
    bindings_[i] = &buffers_[i];
  }
}

std::vector<TexelBinding> GpuScene::texel_bindings() {
  return {{kNodes, VK_FORMAT_R32G32B32A32_UINT}, {kTraced, VK_FORMAT_R32G32B32A32_UINT}};
}

void GpuScene::write(std::uint32_t binding, const void* data, std::size_t bytes, std::size_t offset) {
  if (bytes == 0) return;
  Buffer& b = buffers_[binding];
  // A shader sees at most the device's storage buffer range of a storage buffer (lavapipe:
  // 128 MiB), and maxTexelBufferElements texels of a texel buffer (lavapipe: 2 GiB of RGBA32UI).
  const bool texels = binding == kNodes || binding == kTraced;
  const VkDeviceSize range = texels ? VkDeviceSize(context_.info().max_texel_buffer_elements) * 16
                                    : context_.info().max_storage_buffer_range;
  if (offset + bytes > range) {
    static constexpr const char* kNames[] = {"positions", "triangles",         "meshes",
                                             "instances", "header",            "nodes",
                                             "indices",   "traced triangles"};
    throw Error("vulkan: the scene's " + std::string(kNames[binding]) + " take " +
                std::to_string((offset + bytes) >> 20) + " MiB, more than the device's " +
                std::to_string(range >> 20) + " MiB " +
                (texels ? "texel buffer range" : "storage buffer range"));
  }
  if (b.size() < offset + bytes) {
    // Only whole-buffer writes grow a buffer (partial ones land in an array of unchanged size);
    // a quarter of slack lets the next few growths reuse it.
    SPECULA_ASSERT(offset == 0);
    // The slack stays within the range too: the descriptor binds the whole buffer.
    b = context_.make_buffer(
        std::min<std::size_t>(std::max<std::size_t>(bytes + bytes / 4, 16), range));
    bindings_[binding] = &b;
  }
  b.upload(data, bytes, offset);
  upload_.bytes += bytes;
  ++upload_.writes;
}

// ---- Flattening ----------------------------------------------------------------------------------

void GpuScene::flatten(const SceneTables& tables) {
  header_ = GpuSceneHeader{};
  header_.instance_count = size32(tables.instances.size());
  header_.box_far_scale = accel::kBoxFarScale;
  header_.top_node_base = header_.top_index_base = kNoIndex;
  nodes_.clear();
  words_.clear();
  traced_.clear();
  blas_.clear();

  // ---- The static set: triangles in its structure's order, the structure, the slot lookup -------
  const std::span<const std::uint32_t> first = native_.static_first_triangles();
  const std::span<const std::uint32_t> slots = native_.static_slots();
  for (const std::uint32_t slot : slots) append_triangles(traced_, tables, tables.instances[slot].mesh);
  std::uint32_t static_depth = 0;
  if (native_.has_static() && structure_ == GpuStructure::bvh) {
    const accel::Bvh& bvh = native_.static_bvh();
    bvh.expand_all();
    header_.static_kind = kStaticBvh;
    header_.static_node_base = size32(nodes_.size());
    header_.static_index_base = size32(words_.size());
    append_nodes(nodes_, bvh.nodes());
    append(words_, bvh.indices());
    static_depth = bvh.stats().max_depth;
  } else if (native_.has_static() && !native_.grid().empty()) {
    const accel::UniformGrid& grid = native_.grid();
    header_.static_kind = kStaticGrid;
    header_.grid = grid.header();
    header_.static_index_base = size32(words_.size());
    append(words_, grid.indices());
    header_.cell_start_base = size32(words_.size());
    append(words_, grid.cell_start());
  }
  header_.static_first_base = size32(words_.size());
  append(words_, first);
  header_.static_slot_base = size32(words_.size());
  append(words_, slots);
  header_.static_instances = size32(slots.size());

  // ---- Each distinct per-mesh BVH once, in the top level's box order ----------------------------
  std::uint32_t blas_depth = 0;
  for (std::size_t box = 0; box < native_.top_entry_count(); ++box) {
    const NativeTracer::TopEntry e = native_.top_entry(box);
    if (blas_.contains(e.blas)) continue;
    e.blas->expand_all();
    blas_[e.blas] = {size32(nodes_.size()), size32(words_.size()),
                     size32(traced_.size() / kTracedWords)};
    append_nodes(nodes_, e.blas->nodes());
    append(words_, e.blas->indices());
    append_triangles(traced_, tables, tables.instances[e.slot].mesh);
    blas_depth = std::max(blas_depth, e.blas->stats().max_depth);
  }

  // ---- The top level, last ------------------------------------------------------------------------
  top_ = flatten_top();
  header_.top_count = size32(top_.entries.size());
  if (!top_.entries.empty()) {
    header_.top_node_base = size32(nodes_.size());
    header_.top_index_base = size32(words_.size());
    append<GpuNode>(nodes_, top_.nodes);
    append<std::uint32_t>(words_, top_.indices);
  }
  const std::uint32_t top_depth = top_.entries.empty() ? 0 : native_.top_level().stats().max_depth;
  stack_depth_ = std::max(static_depth, top_depth + blas_depth) + 2;
  if (stack_depth_ > kTraceStackSize)
    throw Error("vulkan: the scene's trees need " + std::to_string(stack_depth_) +
                " traversal stack entries, more than the kernels' " +
                std::to_string(kTraceStackSize));
}

GpuScene::TopLayout GpuScene::flatten_top() const {
  TopLayout top;
  const std::size_t count = native_.top_entry_count();
  top.entries.reserve(count);
  for (std::size_t box = 0; box < count; ++box) {
    const NativeTracer::TopEntry e = native_.top_entry(box);
    const auto place = blas_.find(e.blas);
    if (place == blas_.end()) return {}; // a BVH not laid out yet: the caller uploads everything
    GpuTopEntry g{};
    g.c0 = vec3(e.object_from_world[0]);
    g.c1 = vec3(e.object_from_world[1]);
    g.c2 = vec3(e.object_from_world[2]);
    g.c3 = vec3(e.object_from_world[3]);
    g.slot = e.slot;
    g.node_base = place->second.node_base;
    g.index_base = place->second.index_base;
    g.tri_base = place->second.tri_base;
    g.identity = e.identity ? 1u : 0u;
    top.entries.push_back(g);
  }
  if (count > 0) {
    const accel::Bvh& bvh = native_.top_level();
    append_nodes(top.nodes, bvh.nodes());
    top.indices.assign(bvh.indices().begin(), bvh.indices().end());
  }
  return top;
}

// ---- Uploads -------------------------------------------------------------------------------------

void GpuScene::write_header() {
  std::vector<std::uint8_t> bytes(sizeof(GpuSceneHeader) + top_.entries.size() * sizeof(GpuTopEntry));
  std::memcpy(bytes.data(), &header_, sizeof header_);
  if (!top_.entries.empty())
    std::memcpy(bytes.data() + sizeof header_, top_.entries.data(),
                top_.entries.size() * sizeof(GpuTopEntry));
  write(kHeader, bytes.data(), bytes.size());
}

void GpuScene::upload_all(const SceneTables& tables) {
  flatten(tables);
  upload_.full = true;
  write_vector(kPositions, tables.positions);
  write_vector(kTriangles, tables.triangles);
  write_vector(kMeshes, tables.meshes);
  write_vector(kInstances, tables.instances);
  write_header();
  write_vector(kNodes, nodes_);
  write_vector(kWords, words_);
  write_vector(kTraced, traced_);
}

bool GpuScene::upload_top() {
  TopLayout top = flatten_top();
  if (top.entries.size() != top_.entries.size() || top.nodes.size() != top_.nodes.size() ||
      top.indices.size() != top_.indices.size() ||
      top.entries.size() != native_.top_entry_count())
    return false;
  if (top.entries.empty()) return true; // still no dynamic instance to trace: nothing to write
  top_ = std::move(top);
  write(kHeader, top_.entries.data(), top_.entries.size() * sizeof(GpuTopEntry),
        sizeof(GpuSceneHeader));
  write(kNodes, top_.nodes.data(), top_.nodes.size() * sizeof(GpuNode),
        std::size_t(header_.top_node_base) * sizeof(GpuNode));
  write(kWords, top_.indices.data(), top_.indices.size() * sizeof(std::uint32_t),
        std::size_t(header_.top_index_base) * sizeof(std::uint32_t));
  return true;
}

const TracerUpdateStats& GpuScene::update(const SceneLayer& layer) {
  // The delta before native_ applies it (both have applied the same syncs).
  const SceneDelta& d = layer.delta_since(synced_);
  synced_ = layer.syncs();
  const TracerUpdateStats& stats = native_.update(layer);
  const SceneTables& tables = layer.tables();
  upload_ = GpuUploadStats{};
  const bool full = !uploaded_ || d.full || d.static_rebuilt || d.geometry_relocated ||
                    !d.meshes_added.empty() || !d.meshes_removed.empty() ||
                    !d.instances_added.empty() || !d.instances_removed.empty();
  if (full) {
    upload_all(tables);
    uploaded_ = true;
    return stats;
  }
  // Moved instances: their table entries (the transforms shading reads).
  for (const std::uint32_t slot : d.instances_moved)
    write(kInstances, &tables.instances[slot], sizeof(GpuInstance), slot * sizeof(GpuInstance));
  // Deformed instances: their vertices and mesh record, then the node array (refitted, perhaps
  // restructured: its size may change, so it is laid out again with everything that follows it).
  for (const std::uint32_t slot : d.instances_deformed) {
    const std::uint32_t mesh = tables.instances[slot].mesh;
    const GpuMesh& m = tables.meshes[mesh];
    write(kPositions, &tables.positions[m.first_vertex], m.vertex_count * sizeof(vec3),
          m.first_vertex * sizeof(vec3));
    write(kMeshes, &m, sizeof m, mesh * sizeof(GpuMesh));
  }
  if (!d.instances_deformed.empty()) {
    flatten(tables);
    write_header();
    write_vector(kNodes, nodes_);
    write_vector(kWords, words_);
    write_vector(kTraced, traced_); // the moved vertices' copies
  } else if (!d.instances_moved.empty() && !upload_top()) {
    upload_all(tables); // the top level changed shape (an instance hidden or shown)
  }
  return stats;
}

} // namespace specula::gpu

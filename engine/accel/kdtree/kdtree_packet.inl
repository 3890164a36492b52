// The packet kd-tree traversal, included twice by kdtree.cpp: once for SSE (Vf = __m128, 4 lanes)
// and once for AVX2 (Vf = __m256, 8 lanes, every function with the avx2 target attribute). The
// includer brings in kLanes, Vf, the v* operations and the lanes' watertight test (simd_lanes.h)
// and defines SPECULA_SIMD_TARGET.
//
// Wald, Slusallek, Benthin & Wagner, "Interactive Rendering with Coherent Ray Tracing" (2001), §4:
// rays sharing the sign of their direction on every axis agree on which child of a node is the near
// one, so the packet walks the tree as one ray with per-lane intervals and an active mask: it goes
// to the near child only, the far child only, or to both (far on the stack) when its lanes differ.
// Leaves test one triangle against all lanes at once (the watertight test, when the lanes share
// their ray space: dominant axis and shear axes; simd_lanes.h) or each lane with the scalar test.

/// Traverses the lanes in `mask` (bits), whose directions all have the signs `neg`, from the root
/// over their box intervals [tmin_in, tmax_in]. `w`: the lanes (prepare_coherent_lanes or
/// make_watertight_lanes), `shared_axes` whether they share their ray space (then leaves test them
/// all at once). Closer hits land in `hits` and rays[i].tfar. AnyHit (occlusion): a lane that
/// finds a hit in a leaf leaves the walk, which ends when every lane has; returns those lanes.
template <TriangleTest Test, bool AnyHit = false>
SPECULA_SIMD_TARGET unsigned traverse_packet(const KdView& kd, PreparedRay* rays, TriangleHit* hits,
                                             const float* tmin_in, const float* tmax_in,
                                             unsigned mask, const std::uint32_t neg[3],
                                             const WatertightLanes& w, bool shared_axes) {
  const Vf* org = w.org;
  const Vf* inv = w.inv;
  const Vf down = vset1(kDown), up = vset1(kUp);
  Vf tmin = vload(tmin_in), tmax = vload(tmax_in);
  Vf tfar = load_tfar(rays);

  struct Entry {
    Vf tmin, tmax;
    std::uint32_t node;
    unsigned mask;
  };
  Entry stack[kStackSize];
  int sp = 0;
  std::uint32_t node = 0;
  unsigned blocked = 0;
  for (;;) {
    const gpu::KdNode n = kd.nodes[node];
    const std::uint32_t axis = n.bits & 3u;
    if (axis != gpu::kKdLeaf) {
      const Vf t_split = vmul(vsub(vset1(n.split), org[axis]), inv[axis]);
      // A NaN split distance (a ray in the plane, parallel to it) needs both children. As in the
      // single-ray walk, a plane at or behind the origin leaves only the far child (a lane that
      // starts on the plane and moves away does not visit the near one over an empty interval).
      const Vf nan = vnan(t_split);
      const unsigned need_near =
          mask & vmask(vor(vand(vge(t_split, vmul(tmin, down)), vgt(t_split, vzero())), nan));
      const unsigned need_far = mask & vmask(vor(vle(t_split, vmul(tmax, up)), nan));
      const std::uint32_t below = node + 1, above = n.bits >> 2;
      const std::uint32_t near_child = neg[axis] ? above : below;
      const std::uint32_t far_child = neg[axis] ? below : above;
      if (need_far == 0 && need_near != 0) {
        node = near_child;
        mask = need_near;
        tmax = vmin(t_split, tmax);
        continue;
      }
      if (need_near == 0 && need_far != 0) {
        node = far_child;
        mask = need_far;
        tmin = vmax(t_split, tmin);
        continue;
      }
      if (need_near != 0) {
        stack[sp++] = {vmax(t_split, tmin), tmax, far_child, need_far};
        node = near_child;
        mask = need_near;
        tmax = vmin(t_split, tmax);
        continue;
      }
    } else {
      const std::uint32_t count = n.bits >> 2;
      const std::uint32_t* ids = kd.indices + n.first;
      if (Test == TriangleTest::watertight && shared_axes && count != 0) {
        intersect_leaf_lanes(w, rays, hits, tfar, mask, *kd.tris, ids, count); // tfar kept current
      } else if (count != 0) {
        for (unsigned m = mask; m; m &= m - 1) {
          const int i = std::countr_zero(m);
          intersect_leaf<Test>(rays[i], *kd.tris, ids, count, hits[i]);
        }
        tfar = load_tfar(rays);
      }
      if constexpr (AnyHit) {
        for (unsigned m = mask; m; m &= m - 1)
          if (hits[std::countr_zero(m)].hit()) blocked |= 1u << std::countr_zero(m);
      }
    }
    // Pop the nearest pending cell with lanes that still reach it (each entry culled on its own,
    // as in the single-ray traversal: lanes in a split plane make the stack unsorted).
    for (;;) {
      if (sp == 0) return blocked;
      const Entry& e = stack[--sp];
      mask = e.mask & ~blocked & ~vmask(vlt(tfar, vmul(e.tmin, down)));
      if (mask == 0) continue;
      node = e.node;
      tmin = e.tmin;
      tmax = e.tmax;
      break;
    }
  }
}

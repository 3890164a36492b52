// The 4-wide BVH's packet traversal, included by wide_bvh.cpp twice: once for SSE (Vf = __m128,
// 4 lanes) and once for AVX2 (Vf = __m256, 8 lanes, every function with the avx2 target
// attribute). The includer brings in kLanes, Vf, the v* operations and the lanes' watertight test
// (simd_lanes.h), and defines SPECULA_SIMD_TARGET.
//
// A packet whose lanes share their direction signs and their ray space (prepare_coherent_lanes)
// walks the tree as one: at each node the four child boxes are tested against all lanes (the
// slab test of intersect_box, lane-wise, the same operations), each child is entered with the
// lanes that hit it, nearest first by the least entry distance over those lanes, and a leaf's
// triangles are tested one at a time against all its lanes, with the single-ray test's bits. A
// lane's closest hit is its single ray's, but where two triangles meet and their hits lie an ulp
// or so apart: a box whose rounded entry lies past the nearer hit found so far is skipped, so the
// order of the visit decides which of the two is kept (as between any two structures here).

/// Walks the lanes in `mask` (their signs `neg`, their lanes `w`) from the root; closer hits land
/// in `hits` and rays[i].tfar.
SPECULA_SIMD_TARGET void traverse_packet(const WideBvhNode* nodes, const WideTriangles* groups,
                                         PreparedRay* rays, TriangleHit* hits, unsigned mask,
                                         const std::uint32_t neg[3], const WatertightLanes& w) {
  const Vf scale = vset1(kBoxFarScale);
  Vf tfar = load_tfar(rays);

  struct Entry {
    std::uint32_t child, count; ///< as in WideBvhNode: count 0 is an interior node
    unsigned mask;              ///< the lanes that entered it
    float t;                    ///< the least entry distance over those lanes
  };
  Entry stack[WideBvh::kStackSize];
  int top = 0;
  Entry cur{0, 0, mask, 0.0f};
  for (;;) {
    if (cur.count == 0) {
      const WideBvhNode& n = nodes[cur.child];
      const Vf lanes = vlanes(cur.mask);
      Entry hit[4];
      int k = 0;
      for (int c = 0; c < 4; ++c) {
        Vf t0 = w.tnear, t1 = tfar;
        for (int a = 0; a < 3; ++a) {
          const Vf lo = vset1(n.lo[a][c]);
          const Vf hi = vset1(n.hi[a][c]);
          const Vf tn = vmul(vsub(neg[a] != 0 ? hi : lo, w.org[a]), w.inv[a]);
          const Vf tf = vmul(vmul(vsub(neg[a] != 0 ? lo : hi, w.org[a]), w.inv[a]), scale);
          t0 = vmax(tn, t0); // NaN keeps the current bound, as intersect_box's comparisons do
          t1 = vmin(tf, t1);
        }
        const Vf in = vand(vle(t0, t1), lanes);
        const unsigned m = vmask(in);
        if (m == 0) continue;
        // The least entry over the lanes that enter (never NaN: vmax kept the finite bound), by
        // vector steps rather than a loop over the lanes, which branched on which ones entered.
        const float least = vhmin(vselect(vset1(std::numeric_limits<float>::infinity()), t0, in));
        // Sorted nearest first (an insertion into at most three).
        Entry e{n.child[c], n.count[c], m, least};
        int j = k++;
        for (; j > 0 && hit[j - 1].t > e.t; --j) hit[j] = hit[j - 1];
        hit[j] = e;
      }
      if (k > 0) {
        for (int j = k - 1; j > 0; --j) stack[top++] = hit[j];
        cur = hit[0];
        continue;
      }
    } else {
      const WideTriangles* g = groups + cur.child;
      for (std::uint32_t q = 0; q < cur.count; ++q) {
        for (int i = 0; i < 4 && g[q].prim[i] != 0xFFFFFFFFu; ++i) {
          const vec3 p0 = vertex(g[q], 0, i), p1 = vertex(g[q], 1, i), p2 = vertex(g[q], 2, i);
          const std::uint32_t prim = g[q].prim[i];
          intersect_watertight_lanes(
              w, rays, hits, tfar, cur.mask, p0, p1, p2, prim,
              [&](int lane) { closest_triangle_lane(rays[lane], p0, p1, p2, prim, hits[lane]); });
        }
      }
    }
    // The next pending child that some of its lanes still reach (their tfar may have shrunk).
    for (;;) {
      if (top == 0) return;
      cur = stack[--top];
      cur.mask &= ~vmask(vlt(tfar, vset1(cur.t)));
      if (cur.mask != 0) break;
    }
  }
}

/// Occlusion of the lanes in `mask` (their signs `neg`, their lanes `w`) from the root: returns
/// the lanes that meet a triangle within (tnear, tfar). A lane leaves the walk once blocked, and
/// the walk ends when every lane has; children are entered in their order (any hit will do, as in
/// the single ray's occlusion walk). A subtree that one lane alone enters goes to
/// `single(lane, child, count)`, that lane's single-ray walk from there (it returns whether the
/// lane is blocked): divergent shadow rays soon leave one lane per subtree, and the vector steps
/// would work for the idle ones. A lane's answer is its single ray's: the same box and triangle
/// tests, and its tfar never shrinks before it is blocked.
template <class Single>
SPECULA_SIMD_TARGET unsigned occlude_packet(const WideBvhNode* nodes, const WideTriangles* groups,
                                            PreparedRay* rays, unsigned mask,
                                            const std::uint32_t neg[3], const WatertightLanes& w,
                                            Single&& single) {
  const Vf scale = vset1(kBoxFarScale);
  Vf tfar = load_tfar(rays);

  struct Entry {
    std::uint32_t child, count; ///< as in WideBvhNode: count 0 is an interior node
    unsigned mask;              ///< the lanes that entered it
  };
  Entry stack[WideBvh::kStackSize];
  int top = 0;
  const unsigned all = mask;
  unsigned blocked = 0;
  TriangleHit scratch[kLanes];
  Entry cur{0, 0, mask};
  for (;;) {
    if ((cur.mask & (cur.mask - 1)) == 0) { // one lane (cur.mask is never 0 here)
      // One lane left in this subtree: its own walk (no vector work for seven idle lanes).
      if (single(std::countr_zero(cur.mask), cur.child, cur.count)) {
        blocked |= cur.mask;
        if (blocked == all) return blocked;
      }
    } else if (cur.count == 0) {
      const WideBvhNode& n = nodes[cur.child];
      int taken = -1;
      unsigned taken_mask = 0;
      for (int c = 0; c < 4; ++c) {
        Vf t0 = w.tnear, t1 = tfar;
        for (int a = 0; a < 3; ++a) {
          const Vf lo = vset1(n.lo[a][c]);
          const Vf hi = vset1(n.hi[a][c]);
          const Vf tn = vmul(vsub(neg[a] != 0 ? hi : lo, w.org[a]), w.inv[a]);
          const Vf tf = vmul(vmul(vsub(neg[a] != 0 ? lo : hi, w.org[a]), w.inv[a]), scale);
          t0 = vmax(tn, t0); // NaN keeps the current bound, as intersect_box's comparisons do
          t1 = vmin(tf, t1);
        }
        const unsigned m = cur.mask & vmask(vle(t0, t1));
        if (m == 0) continue;
        if (taken >= 0) {
          stack[top++] = Entry{n.child[c], n.count[c], m};
        } else {
          taken = c;
          taken_mask = m;
        }
      }
      if (taken >= 0) {
        cur = Entry{n.child[taken], n.count[taken], taken_mask};
        continue;
      }
    } else {
      const WideTriangles* g = groups + cur.child;
      for (std::uint32_t q = 0; q < cur.count && cur.mask != 0; ++q) {
        for (int i = 0; i < 4 && g[q].prim[i] != 0xFFFFFFFFu && cur.mask != 0; ++i) {
          const vec3 p0 = vertex(g[q], 0, i), p1 = vertex(g[q], 1, i), p2 = vertex(g[q], 2, i);
          unsigned edge_hits = 0;
          const unsigned hit = intersect_watertight_lanes(
              w, rays, scratch, tfar, cur.mask, p0, p1, p2, g[q].prim[i], [&](int lane) {
                if (any_triangle_lane(rays[lane], p0, p1, p2)) edge_hits |= 1u << lane;
              });
          blocked |= hit | edge_hits;
          cur.mask &= ~(hit | edge_hits);
        }
      }
      if (blocked == all) return blocked;
    }
    // The next pending child that some of its lanes, not yet blocked, reach.
    for (;;) {
      if (top == 0) return blocked;
      cur = stack[--top];
      cur.mask &= ~blocked;
      if (cur.mask != 0) break;
    }
  }
}

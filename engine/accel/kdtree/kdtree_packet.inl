// The packet kd-tree traversal, included twice by kdtree.cpp: once for SSE (Vf = __m128, 4 lanes)
// and once for AVX2 (Vf = __m256, 8 lanes, every function with the avx2 target attribute). The
// includer defines kLanes, Vf, the v* operations and SPECULA_KD_TARGET.
//
// Wald, Slusallek, Benthin & Wagner, "Interactive Rendering with Coherent Ray Tracing" (2001), §4:
// rays sharing the sign of their direction on every axis agree on which child of a node is the near
// one, so the packet walks the tree as one ray with per-lane intervals and an active mask: it goes
// to the near child only, the far child only, or to both (far on the stack) when its lanes differ.
// Leaves test one triangle against all lanes at once (the watertight test, when the lanes share
// their ray space: dominant axis and shear axes) or each lane with the scalar test.

SPECULA_KD_TARGET inline Vf load_tfar(const PreparedRay* rays) {
  alignas(32) float lane[kLanes];
  for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].tfar;
  return vload(lane);
}

SPECULA_KD_TARGET inline Vf gather(const PreparedRay* rays, float PreparedRay::*field) {
  alignas(32) float lane[kLanes];
  for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].*field;
  return vload(lane);
}

/// What the SIMD watertight test needs of the lanes, which share their axes kx, ky, kz.
struct WatertightLanes {
  Vf org[3];
  Vf sx, sy, sz, tnear;
  int kx, ky, kz;
};

/// One triangle against the lanes in `mask`: Woop et al.'s test with the scalar test's operations
/// in the scalar test's order, so every lane gets the bits intersect_watertight would give it.
/// Lanes with an edge function of exactly 0 take the scalar test (its double-precision fallback).
SPECULA_KD_TARGET inline void
intersect_watertight_lanes(const WatertightLanes& w, PreparedRay* rays, TriangleHit* hits, Vf& tfar,
                           unsigned mask, const TriangleView& tris, std::uint32_t prim) {
  const uvec3 tri = tris.triangles[prim];
  const vec3& p0 = tris.positions[tri.x];
  const vec3& p1 = tris.positions[tri.y];
  const vec3& p2 = tris.positions[tri.z];
  const Vf a_kx = vsub(vset1(p0[w.kx]), w.org[w.kx]);
  const Vf a_ky = vsub(vset1(p0[w.ky]), w.org[w.ky]);
  const Vf a_kz = vsub(vset1(p0[w.kz]), w.org[w.kz]);
  const Vf b_kx = vsub(vset1(p1[w.kx]), w.org[w.kx]);
  const Vf b_ky = vsub(vset1(p1[w.ky]), w.org[w.ky]);
  const Vf b_kz = vsub(vset1(p1[w.kz]), w.org[w.kz]);
  const Vf c_kx = vsub(vset1(p2[w.kx]), w.org[w.kx]);
  const Vf c_ky = vsub(vset1(p2[w.ky]), w.org[w.ky]);
  const Vf c_kz = vsub(vset1(p2[w.kz]), w.org[w.kz]);
  const Vf ax = vsub(a_kx, vmul(w.sx, a_kz));
  const Vf ay = vsub(a_ky, vmul(w.sy, a_kz));
  const Vf bx = vsub(b_kx, vmul(w.sx, b_kz));
  const Vf by = vsub(b_ky, vmul(w.sy, b_kz));
  const Vf cx = vsub(c_kx, vmul(w.sx, c_kz));
  const Vf cy = vsub(c_ky, vmul(w.sy, c_kz));
  const Vf U = vsub(vmul(cx, by), vmul(cy, bx));
  const Vf V = vsub(vmul(ax, cy), vmul(ay, cx));
  const Vf W = vsub(vmul(bx, ay), vmul(by, ax));
  const Vf zero = vzero();
  const unsigned on_edge = mask & vmask(vor(vor(veq(U, zero), veq(V, zero)), veq(W, zero)));
  const Vf outside = vand(vor(vor(vlt(U, zero), vlt(V, zero)), vlt(W, zero)),
                          vor(vor(vgt(U, zero), vgt(V, zero)), vgt(W, zero)));
  unsigned candidates = mask & ~on_edge & ~vmask(outside);
  if (candidates != 0) {
    const Vf det = vadd(vadd(U, V), W);
    const Vf az = vmul(w.sz, a_kz);
    const Vf bz = vmul(w.sz, b_kz);
    const Vf cz = vmul(w.sz, c_kz);
    const Vf T = vadd(vadd(vmul(U, az), vmul(V, bz)), vmul(W, cz));
    const Vf sign = vset1(-0.0f);
    const Vf abs_det = vxor(det, vand(det, sign));
    const Vf signed_t = vxor(T, vand(det, sign));
    const Vf inv_det = vdiv(vset1(1.0f), det);
    const Vf t = vmul(T, inv_det);
    const Vf ok =
        vand(vand(vgt(signed_t, vmul(w.tnear, abs_det)), vlt(signed_t, vmul(tfar, abs_det))),
             vand(vgt(t, w.tnear), vlt(t, tfar)));
    candidates &= ~vmask(veq(det, zero)) & vmask(ok);
    if (candidates != 0) {
      alignas(32) float t_lane[kLanes], u_lane[kLanes], v_lane[kLanes];
      vstore(t_lane, t);
      vstore(u_lane, vmul(V, inv_det));
      vstore(v_lane, vmul(W, inv_det));
      for (unsigned m = candidates; m; m &= m - 1) {
        const int i = std::countr_zero(m);
        rays[i].tfar = t_lane[i];
        hits[i] = TriangleHit{t_lane[i], u_lane[i], v_lane[i], prim};
      }
    }
  }
  for (unsigned m = on_edge; m; m &= m - 1) {
    const int i = std::countr_zero(m);
    intersect_leaf<TriangleTest::watertight>(rays[i], tris, &prim, 1, hits[i]);
  }
  if ((candidates | on_edge) != 0) tfar = gather(rays, &PreparedRay::tfar);
}

/// Traverses the lanes in `mask` (bits), whose directions all have the signs `neg`, from the root
/// over their box intervals [tmin_in, tmax_in]. Closer hits land in `hits` and rays[i].tfar.
template <TriangleTest Test>
SPECULA_KD_TARGET void traverse_packet(const KdView& kd, PreparedRay* rays, TriangleHit* hits,
                                       const float* tmin_in, const float* tmax_in, unsigned mask,
                                       const std::uint32_t neg[3]) {
  alignas(32) float lane[kLanes];
  Vf org[3], inv[3];
  for (int a = 0; a < 3; ++a) {
    for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].org[a];
    org[a] = vload(lane);
    for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].inv_dir[a];
    inv[a] = vload(lane);
  }
  // The SIMD triangle test needs one ray space for all lanes (camera packets have it).
  const int lead = std::countr_zero(mask);
  bool shared_axes = true;
  for (unsigned m = mask; m; m &= m - 1) {
    const PreparedRay& r = rays[std::countr_zero(m)];
    shared_axes =
        shared_axes && r.kx == rays[lead].kx && r.ky == rays[lead].ky && r.kz == rays[lead].kz;
  }
  WatertightLanes w;
  for (int a = 0; a < 3; ++a) w.org[a] = org[a];
  w.sx = gather(rays, &PreparedRay::sx);
  w.sy = gather(rays, &PreparedRay::sy);
  w.sz = gather(rays, &PreparedRay::sz);
  w.tnear = gather(rays, &PreparedRay::tnear);
  w.kx = rays[lead].kx;
  w.ky = rays[lead].ky;
  w.kz = rays[lead].kz;
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
  for (;;) {
    const gpu::KdNode n = kd.nodes[node];
    const std::uint32_t axis = n.bits & 3u;
    if (axis != gpu::kKdLeaf) {
      const Vf t_split = vmul(vsub(vset1(n.split), org[axis]), inv[axis]);
      // A NaN split distance (a ray in the plane, parallel to it) needs both children.
      const Vf nan = vnan(t_split);
      const unsigned need_near = mask & vmask(vor(vge(t_split, vmul(tmin, down)), nan));
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
        for (std::uint32_t k = 0; k < count; ++k)
          intersect_watertight_lanes(w, rays, hits, tfar, mask, *kd.tris, ids[k]);
      } else {
        for (unsigned m = mask; m; m &= m - 1) {
          const int i = std::countr_zero(m);
          intersect_leaf<Test>(rays[i], *kd.tris, ids, count, hits[i]);
        }
      }
      if (count != 0) tfar = load_tfar(rays);
    }
    // Pop the nearest pending cell with lanes that still reach it (each entry culled on its own,
    // as in the single-ray traversal: lanes in a split plane make the stack unsorted).
    for (;;) {
      if (sp == 0) return;
      const Entry& e = stack[--sp];
      mask = e.mask & ~vmask(vlt(tfar, vmul(e.tmin, down)));
      if (mask == 0) continue;
      node = e.node;
      tmin = e.tmin;
      tmax = e.tmax;
      break;
    }
  }
}

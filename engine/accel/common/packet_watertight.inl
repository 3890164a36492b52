// The watertight triangle test over a packet's lanes, included by simd_lanes.h once per width
// (SSE: Vf = __m128, 4 lanes; AVX2: Vf = __m256, 8 lanes, every function with the avx2 target
// attribute). The includer defines kLanes, Vf, the v* operations and SPECULA_SIMD_TARGET.

SPECULA_SIMD_TARGET inline Vf load_tfar(const PreparedRay* rays) {
  alignas(32) float lane[kLanes];
  for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].tfar;
  return vload(lane);
}

SPECULA_SIMD_TARGET inline Vf gather(const PreparedRay* rays, float PreparedRay::*field) {
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
SPECULA_SIMD_TARGET inline void
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

/// The lanes' ray space for the SIMD test: true when every lane in `mask` shares the axes kx, ky,
/// kz (camera packets do); otherwise the lanes take the scalar test.
SPECULA_SIMD_TARGET inline bool make_watertight_lanes(const PreparedRay* rays, unsigned mask,
                                                       WatertightLanes& w) {
  const int lead = std::countr_zero(mask);
  bool shared_axes = true;
  for (unsigned m = mask; m; m &= m - 1) {
    const PreparedRay& r = rays[std::countr_zero(m)];
    shared_axes =
        shared_axes && r.kx == rays[lead].kx && r.ky == rays[lead].ky && r.kz == rays[lead].kz;
  }
  for (int a = 0; a < 3; ++a) {
    alignas(32) float lane[kLanes];
    for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].org[a];
    w.org[a] = vload(lane);
  }
  w.sx = gather(rays, &PreparedRay::sx);
  w.sy = gather(rays, &PreparedRay::sy);
  w.sz = gather(rays, &PreparedRay::sz);
  w.tnear = gather(rays, &PreparedRay::tnear);
  w.kx = rays[lead].kx;
  w.ky = rays[lead].ky;
  w.kz = rays[lead].kz;
  return shared_axes;
}

/// A leaf's triangles against the lanes in `mask` (which share their ray space): closer hits land
/// in hits[i] and rays[i].tfar.
SPECULA_SIMD_TARGET inline void intersect_leaf_lanes(const WatertightLanes& w, PreparedRay* rays,
                                                      TriangleHit* hits, unsigned mask,
                                                      const TriangleView& tris,
                                                      const std::uint32_t* ids,
                                                      std::uint32_t count) {
  Vf tfar = load_tfar(rays);
  for (std::uint32_t k = 0; k < count; ++k)
    intersect_watertight_lanes(w, rays, hits, tfar, mask, tris, ids[k]);
}

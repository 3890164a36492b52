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

/// What the packet kernels need of the lanes: origins and reciprocal directions for the boxes and
/// split planes, and, for the SIMD watertight test, the ray space the lanes share (kx, ky, kz).
struct WatertightLanes {
  Vf org[3], inv[3];
  Vf sx, sy, sz, tnear;
  int kx, ky, kz;
};

/// PreparedRay::make and the root box's intersect_box (with a box) over a packet's lanes in vector
/// steps, with the same operations in the same order (the same bits), for a packet whose traceable
/// active lanes share their direction signs and their watertight ray space (kx, ky, kz), as a
/// camera packet's do. Then `mask` gets the traceable active lanes whose interval meets `box` (all
/// of them without one; tmin and tmax are then not written); each of them its PreparedRay in `out`
/// and its interval in [tmin, tmax] (other lanes: tmin 0, tmax -1); `neg` the shared signs; `w` the
/// lanes (as make_watertight_lanes gives them). Returns false, with nothing written, when the lanes
/// do not agree: the caller then prepares them one by one. (Six divisions and a branchy axis choice
/// per lane, one lane at a time, were about as much time as an 8-wide packet's whole traversal of a
/// small mesh.)
SPECULA_SIMD_TARGET inline bool prepare_coherent_lanes(const RayPacket<kLanes>& rays,
                                                       const bool* active, const Aabb* box,
                                                       PreparedRay* out, float* tmin, float* tmax,
                                                       unsigned& mask, std::uint32_t neg[3],
                                                       WatertightLanes& w) {
  const Vf zero = vzero();
  const Vf sign = vset1(-0.0f);
  const Vf org[3] = {vload(rays.ox), vload(rays.oy), vload(rays.oz)};
  const Vf dir[3] = {vload(rays.dx), vload(rays.dy), vload(rays.dz)};
  const Vf tnear = vload(rays.tnear), tfar = vload(rays.tfar);
  unsigned live = 0;
  for (int i = 0; i < kLanes; ++i) live |= unsigned(active[i]) << i;
  // traceable(): x - x is 0 exactly for finite x (NaN for NaN and ±inf).
  Vf ok = vand(veq(tfar, tfar), vand(vge(tnear, zero), vle(tnear, tfar)));
  ok = vand(ok, vlt(tnear, vset1(std::numeric_limits<float>::infinity())));
  for (int a = 0; a < 3; ++a)
    ok = vand(ok, vand(veq(vsub(org[a], org[a]), zero), veq(vsub(dir[a], dir[a]), zero)));
  const Vf zero_dir = vand(vand(veq(dir[0], zero), veq(dir[1], zero)), veq(dir[2], zero));
  live &= vmask(ok) & ~vmask(zero_dir);
  if (live == 0) {
    mask = 0;
    return true;
  }
  // One sign per axis (std::signbit: the sign bit, as movemask reads it).
  std::uint32_t signs[3];
  for (int a = 0; a < 3; ++a) {
    const unsigned s = vmask(dir[a]) & live;
    if (s != 0 && s != live) return false;
    signs[a] = s != 0 ? 1u : 0u;
  }
  // One dominant axis: kz = |x| > |y| ? (|x| > |z| ? 0 : 2) : (|y| > |z| ? 1 : 2), per lane.
  Vf ad[3];
  for (int a = 0; a < 3; ++a) ad[a] = vxor(dir[a], vand(dir[a], sign));
  const unsigned xy = vmask(vgt(ad[0], ad[1])), xz = vmask(vgt(ad[0], ad[2]));
  const unsigned yz = vmask(vgt(ad[1], ad[2]));
  const unsigned on_axis[3] = {xy & xz, ~xy & yz, (xy & ~xz) | (~xy & ~yz)};
  int kz = 0;
  while (kz < 3 && (on_axis[kz] & live) != live) ++kz;
  if (kz == 3) return false;
  int kx = (kz + 1) % 3, ky = (kx + 1) % 3;
  // dir[kz] < 0 as the sign bit: the dominant component of a traceable ray is not ±0.
  if (signs[kz] != 0) std::swap(kx, ky);

  const Vf one = vset1(1.0f);
  Vf inv[3];
  for (int a = 0; a < 3; ++a) inv[a] = vdiv(one, dir[a]);
  const Vf sx = vdiv(dir[kx], dir[kz]);
  const Vf sy = vdiv(dir[ky], dir[kz]);
  const Vf sz = vdiv(one, dir[kz]);
  mask = live;
  if (box != nullptr) {
    // intersect_box: the slab distances, near and far swapped by the sign, the far one widened.
    Vf t0 = tnear, t1 = tfar;
    const Vf far_scale = vset1(kBoxFarScale);
    for (int a = 0; a < 3; ++a) {
      Vf tn = vmul(vsub(vset1(box->min[a]), org[a]), inv[a]);
      Vf tf = vmul(vsub(vset1(box->max[a]), org[a]), inv[a]);
      if (signs[a] != 0) std::swap(tn, tf);
      tf = vmul(tf, far_scale);
      t0 = vmax(tn, t0); // tn > t0 ? tn : t0, NaN keeping t0
      t1 = vmin(tf, t1);
    }
    mask &= vmask(vle(t0, t1));
    vstore(tmin, t0);
    vstore(tmax, t1);
  }
  alignas(32) float lanes[14][kLanes];
  for (int a = 0; a < 3; ++a) {
    vstore(lanes[a], org[a]);
    vstore(lanes[3 + a], dir[a]);
    vstore(lanes[6 + a], inv[a]);
  }
  vstore(lanes[9], tnear);
  vstore(lanes[10], tfar);
  vstore(lanes[11], sx);
  vstore(lanes[12], sy);
  vstore(lanes[13], sz);
  for (int i = 0; i < kLanes; ++i) {
    if (((mask >> i) & 1u) == 0) {
      if (box != nullptr) {
        tmin[i] = 0.0f;
        tmax[i] = -1.0f;
      }
      continue;
    }
    PreparedRay& r = out[i];
    r.org = vec3(lanes[0][i], lanes[1][i], lanes[2][i]);
    r.dir = vec3(lanes[3][i], lanes[4][i], lanes[5][i]);
    r.inv_dir = vec3(lanes[6][i], lanes[7][i], lanes[8][i]);
    r.tnear = lanes[9][i];
    r.tfar = lanes[10][i];
    r.kx = kx;
    r.ky = ky;
    r.kz = kz;
    r.sx = lanes[11][i];
    r.sy = lanes[12][i];
    r.sz = lanes[13][i];
    for (int a = 0; a < 3; ++a) r.neg[a] = signs[a];
  }
  for (int a = 0; a < 3; ++a) {
    neg[a] = signs[a];
    w.org[a] = org[a];
    w.inv[a] = inv[a];
  }
  w.sx = sx;
  w.sy = sy;
  w.sz = sz;
  w.tnear = tnear;
  w.kx = kx;
  w.ky = ky;
  w.kz = kz;
  return true;
}

/// Triangle (p0, p1, p2), number `prim`, against the lanes in `mask`: Woop et al.'s test with the
/// scalar test's operations in the scalar test's order, so every lane gets the bits
/// intersect_watertight would give it. Lanes with an edge function of exactly 0 go to
/// `on_edge(i)`, which runs the scalar test (its double-precision fallback) on lane i. Returns the
/// other lanes that hit it (their hits and tfar written).
template <class OnEdge>
SPECULA_SIMD_TARGET inline unsigned
intersect_watertight_lanes(const WatertightLanes& w, PreparedRay* rays, TriangleHit* hits, Vf& tfar,
                           unsigned mask, const vec3& p0, const vec3& p1, const vec3& p2,
                           std::uint32_t prim, OnEdge&& on_edge) {
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
  const unsigned edge = mask & vmask(vor(vor(veq(U, zero), veq(V, zero)), veq(W, zero)));
  const Vf outside = vand(vor(vor(vlt(U, zero), vlt(V, zero)), vlt(W, zero)),
                          vor(vor(vgt(U, zero), vgt(V, zero)), vgt(W, zero)));
  unsigned candidates = mask & ~edge & ~vmask(outside);
  Vf hit_t = tfar; // the lanes' tfar after this triangle, without the edge lanes'
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
      hit_t = vselect(tfar, t, vlanes(candidates));
    }
  }
  for (unsigned m = edge; m; m &= m - 1) on_edge(std::countr_zero(m));
  // The edge lanes' scalar test may have moved their tfar: read them all back then.
  tfar = edge != 0 ? gather(rays, &PreparedRay::tfar) : hit_t;
  return candidates;
}

/// Triangle `prim` of `tris` against the lanes in `mask` (as above; a lane on an edge takes
/// intersect_leaf, compiled for the baseline target like the single-ray path).
SPECULA_SIMD_TARGET inline void
intersect_watertight_lanes(const WatertightLanes& w, PreparedRay* rays, TriangleHit* hits, Vf& tfar,
                           unsigned mask, const TriangleView& tris, std::uint32_t prim) {
  const uvec3 tri = tris.triangles[prim];
  intersect_watertight_lanes(
      w, rays, hits, tfar, mask, tris.positions[tri.x], tris.positions[tri.y],
      tris.positions[tri.z], prim,
      [&](int i) { intersect_leaf<TriangleTest::watertight>(rays[i], tris, &prim, 1, hits[i]); });
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
    for (int i = 0; i < kLanes; ++i) lane[i] = rays[i].inv_dir[a];
    w.inv[a] = vload(lane);
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
/// in hits[i] and rays[i].tfar, and in `tfar`, the lanes' tfar kept in a register by the caller
/// (its lanes equal to rays[i].tfar on entry; so on return).
SPECULA_SIMD_TARGET inline void
intersect_leaf_lanes(const WatertightLanes& w, PreparedRay* rays, TriangleHit* hits, Vf& tfar,
                     unsigned mask, const TriangleView& tris, const std::uint32_t* ids,
                     std::uint32_t count) {
  for (std::uint32_t k = 0; k < count; ++k)
    intersect_watertight_lanes(w, rays, hits, tfar, mask, tris, ids[k]);
}

/// The same for a caller without the lanes' tfar in a register.
SPECULA_SIMD_TARGET inline void
intersect_leaf_lanes(const WatertightLanes& w, PreparedRay* rays, TriangleHit* hits, unsigned mask,
                     const TriangleView& tris, const std::uint32_t* ids, std::uint32_t count) {
  Vf tfar = load_tfar(rays);
  intersect_leaf_lanes(w, rays, hits, tfar, mask, tris, ids, count);
}

// One level of the edge-avoiding à-trous filter, written over the vector operations of the
// namespace that includes it (denoise.cpp: sse, 4 lanes; avx2, 8 lanes, with SPECULA_SIMD_TARGET
// naming the target). Not a header: included only there.

/// exp(−e) for e in [0, kMaxExponent], within 2·10⁻⁴ relative: 2^t split into an integer power
/// (written into the float's exponent) and 2^g, g in (0, 1], by its degree-5 Taylor polynomial.
/// The weights need a smooth fall-off, not libm's last bit; this is what makes them cheap.
SPECULA_SIMD_TARGET inline Vf exp_neg(Vf e) {
  const Vf t = vmul(e, vset1(-1.44269504f)); // log2(e) · −e, in [−43.3, 0]
  Vf power, g;
  vsplit(t, power, g); // 2^(n − 1): the exponent field n − 1 + 127 ≥ 83, a normal float
  Vf p = vset1(1.3333558e-3f);
  p = vadd(vmul(p, g), vset1(9.6181291e-3f));
  p = vadd(vmul(p, g), vset1(5.5504109e-2f));
  p = vadd(vmul(p, g), vset1(2.4022651e-1f));
  p = vadd(vmul(p, g), vset1(6.9314718e-1f));
  p = vadd(vmul(p, g), vset1(1.0f));
  return vmul(p, power);
}

SPECULA_SIMD_TARGET inline Vf square(Vf a) { return vmul(a, a); }

/// One level of the edge-avoiding à-trous transform over rows [y0, y1): taps `step` pixels
/// apart, kLanes pixels at a time. Every lane does the same operations in the same order, so a
/// pixel's value depends neither on which rows a thread was given nor on the lane count.
/// kVariance: the colour weight scales with each centre's variance (`inv_sigma_color2` is then
/// 1/σ_v²), and the level writes the variance of its result, Σw²·Var / (Σw)².
template <bool kVariance>
SPECULA_SIMD_TARGET void filter_level(Planes& px, std::uint32_t step, float inv_sigma_color2,
                                      float inv_sigma_normal2, std::size_t y0, std::size_t y1) {
  const std::size_t stride = px.stride, pad = px.pad;
  const auto s = std::ptrdiff_t(step);
  const Vf ic = vset1(inv_sigma_color2);
  const Vf sigma_v2 = vset1(1.0f / inv_sigma_color2); // kVariance: σ_v²
  const Vf in = vset1(inv_sigma_normal2);
  const Vf max_exponent = vset1(kMaxExponent);
  // The centre weighs its kernel weight alone (all distances 0), so the weight sum ≥ 9/64.
  const Vf centre_weight = vset1(kB3[2] * kB3[2]);
  for (std::size_t y = y0; y < y1; ++y) {
    const auto row = [&](const Plane& p) { return p.row(y, stride, pad); };
    for (std::size_t x = 0; x < px.width; x += kLanes) {
      const Vf cr = vload(row(px.colour[0]) + x);
      const Vf cg = vload(row(px.colour[1]) + x);
      const Vf cb = vload(row(px.colour[2]) + x);
      const Vf cnx = vload(row(px.nx) + x);
      const Vf cny = vload(row(px.ny) + x);
      const Vf cnz = vload(row(px.nz) + x);
      const Vf cd = vload(row(px.depth) + x);
      const Vf cgx = vload(row(px.slope_x) + x);
      const Vf cgy = vload(row(px.slope_y) + x);
      const Vf cis = vload(row(px.inv_depth_scale) + x);
      Vf ic_pixel = ic;
      Vf sv = vzero();
      if constexpr (kVariance) {
        const Vf cv = vload(row(px.variance) + x);
        ic_pixel = vdiv(vset1(1.0f), vadd(vmul(cv, sigma_v2), vset1(kVarianceFloor)));
        sv = vmul(vmul(centre_weight, centre_weight), cv);
      }
      Vf sr = vmul(centre_weight, cr);
      Vf sg = vmul(centre_weight, cg);
      Vf sb = vmul(centre_weight, cb);
      Vf sw = centre_weight;
      for (std::ptrdiff_t j = -2; j <= 2; ++j) {
        const std::ptrdiff_t qy = std::ptrdiff_t(y) + j * s;
        if (qy < 0 || qy >= std::ptrdiff_t(px.height)) continue;
        const auto tap_row = [&](const Plane& p) {
          return p.row(std::size_t(qy), stride, pad) + std::ptrdiff_t(x);
        };
        const float* tr = tap_row(px.colour[0]);
        const float* tg = tap_row(px.colour[1]);
        const float* tb = tap_row(px.colour[2]);
        const float* tnx = tap_row(px.nx);
        const float* tny = tap_row(px.ny);
        const float* tnz = tap_row(px.nz);
        const float* td = tap_row(px.depth);
        const float* tu = tap_row(px.usable);
        const float* tv = kVariance ? tap_row(px.variance) : nullptr;
        // The depth the centre's slope predicts at the tap, row part.
        const Vf cd_row = vadd(cd, vmul(cgy, vset1(float(j * s))));
        for (std::ptrdiff_t i = -2; i <= 2; ++i) {
          if (i == 0 && j == 0) continue;
          const std::ptrdiff_t ox = i * s;
          // A tap beyond the padding is farther than the image is wide: outside for every lane.
          if (ox > std::ptrdiff_t(pad) || -ox > std::ptrdiff_t(pad)) continue;
          const Vf qr = vload(tr + ox);
          const Vf qg = vload(tg + ox);
          const Vf qb = vload(tb + ox);
          const Vf dc =
              vadd(vadd(square(vsub(qr, cr)), square(vsub(qg, cg))), square(vsub(qb, cb)));
          const Vf dn =
              vadd(vadd(square(vsub(vload(tnx + ox), cnx)), square(vsub(vload(tny + ox), cny))),
                   square(vsub(vload(tnz + ox), cnz)));
          const Vf predicted = vadd(cd_row, vmul(cgx, vset1(float(ox))));
          const Vf dd = vmul(vsub(vload(td + ox), predicted), cis);
          const Vf e = vadd(vadd(vmul(dc, ic_pixel), vmul(dn, in)), square(dd));
          // NaN (∞ · 0 from a weight turned off) compares false: weight 0, as beyond the cut-off.
          const Vf near = vlt(e, max_exponent);
          const Vf kernel = vset1(kB3[std::size_t(i + 2)] * kB3[std::size_t(j + 2)]);
          const Vf wgt =
              vmul(vand(near, vmul(kernel, exp_neg(vmin(e, max_exponent)))), vload(tu + ox));
          sr = vadd(sr, vmul(wgt, qr));
          sg = vadd(sg, vmul(wgt, qg));
          sb = vadd(sb, vmul(wgt, qb));
          sw = vadd(sw, wgt);
          if constexpr (kVariance) sv = vadd(sv, vmul(square(wgt), vload(tv + ox)));
        }
      }
      const Vf inv = vdiv(vset1(1.0f), sw);
      if constexpr (kVariance)
        vstore(px.next_variance.row(y, stride, pad) + x, vmul(sv, square(inv)));
      vstore(px.next[0].row(y, stride, pad) + x, vmul(sr, inv));
      vstore(px.next[1].row(y, stride, pad) + x, vmul(sg, inv));
      vstore(px.next[2].row(y, stride, pad) + x, vmul(sb, inv));
    }
  }
}

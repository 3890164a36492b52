#pragma once
/// \file
/// Low-discrepancy samples for the stochastic integrators (path, shadow): 4-D Sobol points
/// (Joe & Kuo 2008 direction numbers) with Owen scrambling by hashing (Burley, "Practical
/// Hash-based Owen Scrambling", JCGT 2020, with Vegdahl's permutation hash), shuffled by
/// scrambling the index too. A pixel gets its own scrambling seed; a sample of it is a position
/// in the pixel's sequence (frame × spp + s), so a progressive render continues one sequence
/// across frames, every 2^k samples starting at a multiple of 2^k form a scrambled (0,k,4)-net
/// (stratified: the shadow caster's area-light samples), and nothing depends on the thread or
/// tile that draws it. Each use (camera, light, BSDF, roulette) at each bounce reads its own
/// "set" of 4 dimensions, decorrelated by hashing the set number into the seed.

#include "specula/core/math.h"

#include <array>
#include <cstdint>

namespace specula {

namespace sobol_detail {

/// Direction numbers of one dimension: dimension 0 is van der Corput; the others follow Joe &
/// Kuo's recurrence for primitive polynomial degree s, coefficients a and initial m.
struct Primitive {
  std::uint32_t s, a;
  std::array<std::uint32_t, 3> m;
};

constexpr std::array<std::uint32_t, 32> directions(const Primitive& p, bool van_der_corput) {
  std::array<std::uint32_t, 32> v{};
  if (van_der_corput) {
    for (std::uint32_t i = 0; i < 32; ++i) v[i] = 1u << (31 - i);
    return v;
  }
  for (std::uint32_t i = 0; i < p.s; ++i) v[i] = p.m[i] << (31 - i);
  for (std::uint32_t i = p.s; i < 32; ++i) {
    v[i] = v[i - p.s] ^ (v[i - p.s] >> p.s);
    for (std::uint32_t k = 1; k < p.s; ++k)
      if (((p.a >> (p.s - 1 - k)) & 1u) != 0) v[i] ^= v[i - k];
  }
  return v;
}

inline constexpr std::array<std::array<std::uint32_t, 32>, 4> kDirections{
    directions({0, 0, {0, 0, 0}}, true),
    directions({1, 0, {1, 0, 0}}, false),
    directions({2, 1, {1, 3, 0}}, false),
    directions({3, 1, {1, 3, 1}}, false),
};

/// The generator matrices a byte of the index at a time: kByteTables[d][b][v] is the XOR of the
/// direction numbers of dimension d selected by byte value v in byte b of the index. A scrambled
/// index has all 32 bits set at random, so the bit-at-a-time loop ran 32 unpredictable branches
/// per dimension (most of the shadow caster's time); four table lookups do the same work.
constexpr std::array<std::array<std::array<std::uint32_t, 256>, 4>, 4> byte_tables() {
  std::array<std::array<std::array<std::uint32_t, 256>, 4>, 4> t{};
  for (std::uint32_t d = 0; d < 4; ++d)
    for (std::uint32_t b = 0; b < 4; ++b)
      for (std::uint32_t v = 0; v < 256; ++v) {
        std::uint32_t x = 0;
        for (std::uint32_t bit = 0; bit < 8; ++bit)
          if (((v >> bit) & 1u) != 0) x ^= kDirections[d][8 * b + bit];
        t[d][b][v] = x;
      }
  return t;
}

inline constexpr auto kByteTables = byte_tables();

/// The bytes swapped by one instruction, then the bits within each byte in three steps.
constexpr std::uint32_t reverse_bits(std::uint32_t x) {
  x = __builtin_bswap32(x);
  x = ((x >> 4) & 0x0F0F0F0Fu) | ((x & 0x0F0F0F0Fu) << 4);
  x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
  return ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
}

/// kByteTables with every entry bit-reversed. Reversal commutes with XOR, so a lookup in these
/// gives the reversed Sobol value directly: the scramble below starts from it and saves one
/// reversal per dimension (the CPU's; the device reads kByteTables).
constexpr std::array<std::array<std::array<std::uint32_t, 256>, 4>, 4> reversed_byte_tables() {
  std::array<std::array<std::array<std::uint32_t, 256>, 4>, 4> t = byte_tables();
  for (auto& dimension : t)
    for (auto& byte : dimension)
      for (std::uint32_t& v : byte) v = reverse_bits(v);
  return t;
}

inline constexpr auto kReversedByteTables = reversed_byte_tables();

/// Burley's nested uniform scramble of a value given bit-reversed (rx = reverse_bits(x)): the
/// hash only propagates bits upwards in the reversed value, so it permutes every dyadic interval
/// of x within its parent (Owen scrambling). Returns the scrambled x, in normal bit order.
constexpr std::uint32_t owen_scramble_reversed(std::uint32_t rx, std::uint32_t seed) {
  rx ^= rx * 0x3d20adeau;
  rx += seed;
  rx *= (seed >> 16) | 1u;
  rx ^= rx * 0x05526c56u;
  rx ^= rx * 0x53a22864u;
  return reverse_bits(rx);
}

/// The same scramble of x in normal bit order.
constexpr std::uint32_t owen_scramble(std::uint32_t x, std::uint32_t seed) {
  return owen_scramble_reversed(reverse_bits(x), seed);
}

} // namespace sobol_detail

/// A 32-bit integer hash (lowbias32, Wellons) for seeds.
[[nodiscard]] constexpr std::uint32_t hash_u32(std::uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

[[nodiscard]] constexpr std::uint32_t hash_combine(std::uint32_t seed, std::uint32_t v) {
  return hash_u32(seed ^ (v + 0x9e3779b9u + (seed << 6) + (seed >> 2)));
}

/// Unscrambled Sobol point `index`, dimension d ∈ [0, 4), as a 32-bit fraction.
[[nodiscard]] constexpr std::uint32_t sobol_u32(std::uint32_t index, std::uint32_t d) {
  const auto& t = sobol_detail::kByteTables[d];
  return t[0][index & 0xFFu] ^ t[1][(index >> 8) & 0xFFu] ^ t[2][(index >> 16) & 0xFFu] ^
         t[3][index >> 24];
}

/// reverse_bits(sobol_u32(index, d)), from the reversed tables; dimension 0 (van der Corput,
/// the index reversed) is the index itself.
[[nodiscard]] constexpr std::uint32_t sobol_reversed_u32(std::uint32_t index, std::uint32_t d) {
  if (d == 0) return index;
  const auto& t = sobol_detail::kReversedByteTables[d];
  return t[0][index & 0xFFu] ^ t[1][(index >> 8) & 0xFFu] ^ t[2][(index >> 16) & 0xFFu] ^
         t[3][index >> 24];
}

/// A 32-bit fraction as a float in [0, 1) (24 bits: never rounds up to 1).
[[nodiscard]] constexpr float to_unit_float(std::uint32_t x) {
  return float(x >> 8) * (1.0f / 16777216.0f);
}

/// One set of one sample (PixelSampler::set): its dimensions one at a time, for uses that need
/// fewer than four (each costs a hash and a scramble). dim(d) equals get4(index, set)[d].
class SampleSet {
public:
  constexpr SampleSet(std::uint32_t set_seed, std::uint32_t shuffled)
      : set_seed_(set_seed), shuffled_(shuffled) {}
  [[nodiscard]] constexpr float dim(std::uint32_t d) const {
    return to_unit_float(sobol_detail::owen_scramble_reversed(sobol_reversed_u32(shuffled_, d),
                                                              hash_combine(set_seed_, d + 1)));
  }

private:
  std::uint32_t set_seed_, shuffled_;
};

/// The samples of one pixel (or any stream keyed by an integer) of one render.
class PixelSampler {
public:
  /// `stream`: the pixel's index in the image; `seed`: the render's seed (TraceSettings::seed).
  constexpr PixelSampler(std::uint32_t stream, std::uint32_t seed)
      : seed_(hash_combine(hash_u32(seed), stream)) {}

  /// The sampler whose stream_seed() is `stream_seed`: kept by a path, it spares the two hashes
  /// of the constructor at every vertex.
  [[nodiscard]] static constexpr PixelSampler from_stream_seed(std::uint32_t stream_seed) {
    return PixelSampler(stream_seed, Hashed{});
  }
  /// The stream's own seed (the render's seed and the stream hashed together).
  [[nodiscard]] constexpr std::uint32_t stream_seed() const { return seed_; }

  /// Dimensions 4·set … 4·set+3 of the pixel's sample `index`: an Owen-scrambled, shuffled 4-D
  /// Sobol point, each set scrambled with its own seed.
  [[nodiscard]] constexpr vec4 get4(std::uint32_t index, std::uint32_t set) const {
    const SampleSet s = this->set(index, set);
    return vec4(s.dim(0), s.dim(1), s.dim(2), s.dim(3));
  }

  /// The same point, its dimensions drawn on demand.
  [[nodiscard]] constexpr SampleSet set(std::uint32_t index, std::uint32_t set) const {
    const std::uint32_t set_seed = hash_combine(seed_, set);
    return SampleSet(set_seed, sobol_detail::owen_scramble(index, set_seed));
  }

  /// Dimensions 4·set and 4·set+1 alone: get4(index, set)'s x and y, for uses that need two
  /// (half the work).
  [[nodiscard]] constexpr vec2 get2(std::uint32_t index, std::uint32_t set) const {
    const SampleSet s = this->set(index, set);
    return vec2(s.dim(0), s.dim(1));
  }

  /// Dimensions 4·set and 4·set+1 of many samples of one set (get2(index, set) for every index),
  /// with the set's seeds hashed once rather than per sample.
  class Stream2 {
  public:
    constexpr explicit Stream2(std::uint32_t set_seed)
        : set_seed_(set_seed), seed0_(hash_combine(set_seed, 1)),
          seed1_(hash_combine(set_seed, 2)) {}
    /// From its three seeds (set_seed(), seed0(), seed1() of another).
    constexpr Stream2(std::uint32_t set_seed, std::uint32_t seed0, std::uint32_t seed1)
        : set_seed_(set_seed), seed0_(seed0), seed1_(seed1) {}
    [[nodiscard]] constexpr vec2 get(std::uint32_t index) const {
      const std::uint32_t shuffled = sobol_detail::owen_scramble(index, set_seed_);
      return vec2(to_unit_float(sobol_detail::owen_scramble_reversed(
                      sobol_reversed_u32(shuffled, 0), seed0_)),
                  to_unit_float(sobol_detail::owen_scramble_reversed(
                      sobol_reversed_u32(shuffled, 1), seed1_)));
    }

    [[nodiscard]] constexpr std::uint32_t set_seed() const { return set_seed_; }
    [[nodiscard]] constexpr std::uint32_t seed0() const { return seed0_; }
    [[nodiscard]] constexpr std::uint32_t seed1() const { return seed1_; }

  private:
    std::uint32_t set_seed_, seed0_, seed1_;
  };
  [[nodiscard]] constexpr Stream2 stream2(std::uint32_t set) const {
    return Stream2(hash_combine(seed_, set));
  }

private:
  struct Hashed {}; ///< the seed is a stream seed already
  constexpr PixelSampler(std::uint32_t stream_seed, Hashed) : seed_(stream_seed) {}

  std::uint32_t seed_;
};

} // namespace specula

// The stochastic integrators' samples (trace/sampler.h): stratification of every aligned block of
// 2^m samples, the range, determinism, independence of streams, and the Sobol construction
// against the standard direction numbers.

#include "specula/trace/sample_batch.h"
#include "specula/trace/sampler.h"

#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <random>
#include <set>
#include <vector>

namespace specula {
namespace {

/// Whether the points form a (0,m,2)-net in base 2: for every split m = a + b, each of the 2^m
/// elementary intervals [i / 2^a, (i+1) / 2^a) × [j / 2^b, (j+1) / 2^b) holds exactly one.
bool is_net(const std::vector<vec2>& points, std::uint32_t m) {
  if (points.size() != (std::size_t(1) << m)) return false;
  for (std::uint32_t a = 0; a <= m; ++a) {
    const std::uint32_t b = m - a;
    std::vector<int> count(points.size(), 0);
    for (const vec2& p : points) {
      const auto i = std::uint32_t(p.x * float(1u << a)), j = std::uint32_t(p.y * float(1u << b));
      ++count[(std::size_t(i) << b) | j];
    }
    for (const int c : count)
      if (c != 1) return false;
  }
  return true;
}

TEST(Sampler, EveryAlignedBlockOfTwoToTheMSamplesIsANetInDimensionsZeroAndOne) {
  for (const std::uint32_t seed : {0u, 7u, 123456u})
    for (const std::uint32_t pixel : {0u, 1u, 517u, 204799u})
      for (const std::uint32_t set : {0u, 1u, 5u}) {
        const PixelSampler sampler(pixel, seed);
        for (std::uint32_t m = 0; m <= 10; ++m)
          for (const std::uint32_t block : {0u, 1u, 3u, 1000u}) {
            std::vector<vec2> points;
            for (std::uint32_t k = 0; k < (1u << m); ++k) {
              const vec4 u = sampler.get4((block << m) + k, set);
              points.emplace_back(u.x, u.y);
            }
            EXPECT_TRUE(is_net(points, m)) << "seed " << seed << " pixel " << pixel << " set "
                                           << set << " m " << m << " block " << block;
          }
      }
}

TEST(Sampler, ValuesLieInTheUnitIntervalAndNeverReachOne) {
  const PixelSampler sampler(42, 3);
  for (std::uint32_t k = 0; k < 4096; ++k)
    for (std::uint32_t set = 0; set < 4; ++set) {
      const vec4 u = sampler.get4(k, set);
      for (int d = 0; d < 4; ++d) {
        EXPECT_GE(u[d], 0.0f);
        EXPECT_LT(u[d], 1.0f);
      }
    }
  // The largest fraction rounds down, not up to 1.
  EXPECT_LT(to_unit_float(0xFFFFFFFFu), 1.0f);
}

TEST(Sampler, TheSameArgumentsGiveTheSameSamples) {
  constexpr PixelSampler a(9, 1);
  constexpr vec4 first = a.get4(3, 2); // usable at compile time: nothing hidden in it
  const PixelSampler b(9, 1);
  EXPECT_EQ(b.get4(3, 2), first);
  for (std::uint32_t k = 0; k < 256; ++k) {
    EXPECT_EQ(a.get4(k, 1), b.get4(k, 1));
    const vec4 u = a.get4(k, 3);
    EXPECT_EQ(a.get2(k, 3), vec2(u.x, u.y)) << "get2 is get4's first two dimensions";
  }
  // A set's stream (its seeds hashed once) draws get2's points.
  const PixelSampler::Stream2 stream = a.stream2(5);
  for (std::uint32_t k = 0; k < 4096; k += 7) EXPECT_EQ(stream.get(k), a.get2(k, 5)) << k;
}

TEST(Sampler, TheReversedTablesGiveTheReversedSobolValues) {
  std::mt19937 rng(31);
  for (int i = 0; i < 20000; ++i) {
    const std::uint32_t index = i < 256 ? std::uint32_t(i) : std::uint32_t(rng());
    for (std::uint32_t d = 0; d < 4; ++d)
      ASSERT_EQ(sobol_reversed_u32(index, d), sobol_detail::reverse_bits(sobol_u32(index, d)))
          << "index " << index << " dimension " << d;
  }
}

TEST(Sampler, PixelsSetsAndSeedsGetDifferentSequences) {
  const auto sequence = [](std::uint32_t pixel, std::uint32_t seed, std::uint32_t set) {
    std::vector<float> v;
    const PixelSampler s(pixel, seed);
    for (std::uint32_t k = 0; k < 16; ++k) {
      const vec4 u = s.get4(k, set);
      v.insert(v.end(), {u.x, u.y, u.z, u.w});
    }
    return v;
  };
  std::set<std::vector<float>> seen;
  int made = 0;
  for (std::uint32_t pixel = 0; pixel < 8; ++pixel)
    for (std::uint32_t seed = 0; seed < 4; ++seed)
      for (std::uint32_t set = 0; set < 4; ++set) {
        seen.insert(sequence(pixel, seed, set));
        ++made;
      }
  EXPECT_EQ(seen.size(), std::size_t(made));
  // Within a sample, the four dimensions are scrambled apart too.
  const vec4 u = PixelSampler(5, 0).get4(1, 0);
  EXPECT_TRUE(u.x != u.y && u.y != u.z && u.z != u.w);
}

TEST(Sampler, DirectionNumbersAreJoeAndKuos) {
  // The generator matrices' first eight columns (the direction numbers v_k = m_k / 2^k as 32-bit
  // fractions) of the Sobol sequence's dimensions 1 to 4 with the Joe–Kuo (2008) polynomials and
  // initial numbers (new-joe-kuo-6.21201: d = 2: s 1, a 0, m 1; d = 3: s 2, a 1, m 1 3; d = 4:
  // s 3, a 1, m 1 3 1), as tabulated e.g. in pbrt-v3's SobolMatrices32.
  constexpr std::uint32_t kColumns[4][8] = {{0x80000000, 0x40000000, 0x20000000, 0x10000000,
                                             0x08000000, 0x04000000, 0x02000000, 0x01000000},
                                            {0x80000000, 0xc0000000, 0xa0000000, 0xf0000000,
                                             0x88000000, 0xcc000000, 0xaa000000, 0xff000000},
                                            {0x80000000, 0xc0000000, 0x60000000, 0x90000000,
                                             0xe8000000, 0x5c000000, 0x8e000000, 0xc5000000},
                                            {0x80000000, 0xc0000000, 0x20000000, 0x50000000,
                                             0xf8000000, 0x74000000, 0xa2000000, 0x93000000}};
  for (std::uint32_t d = 0; d < 4; ++d)
    for (std::uint32_t k = 0; k < 8; ++k)
      EXPECT_EQ(sobol_u32(1u << k, d), kColumns[d][k]) << "dimension " << d << " column " << k;
  // The first points in index (not Gray-code) order.
  constexpr float kPoints[4][8] = {{0, 0.5f, 0.25f, 0.75f, 0.125f, 0.625f, 0.375f, 0.875f},
                                   {0, 0.5f, 0.75f, 0.25f, 0.625f, 0.125f, 0.375f, 0.875f},
                                   {0, 0.5f, 0.75f, 0.25f, 0.375f, 0.875f, 0.625f, 0.125f},
                                   {0, 0.5f, 0.75f, 0.25f, 0.125f, 0.625f, 0.875f, 0.375f}};
  for (std::uint32_t d = 0; d < 4; ++d)
    for (std::uint32_t i = 0; i < 8; ++i)
      EXPECT_EQ(to_unit_float(sobol_u32(i, d)), kPoints[d][i])
          << "dimension " << d << " point " << i;
}

TEST(Sampler, TheByteTablesAreTheGeneratorMatrices) {
  // sobol_u32 reads the matrices a byte at a time; the definition is bit at a time.
  const auto by_bits = [](std::uint32_t index, std::uint32_t d) {
    std::uint32_t x = 0;
    for (std::uint32_t bit = 0; bit < 32; ++bit)
      if (((index >> bit) & 1u) != 0) x ^= sobol_detail::kDirections[d][bit];
    return x;
  };
  std::mt19937 rng(11);
  for (int k = 0; k < 20000; ++k) {
    const std::uint32_t index = k < 1024 ? std::uint32_t(k) : std::uint32_t(rng());
    for (std::uint32_t d = 0; d < 4; ++d) ASSERT_EQ(sobol_u32(index, d), by_bits(index, d));
  }
  for (std::uint32_t d = 0; d < 4; ++d)
    EXPECT_EQ(sobol_u32(0xFFFFFFFFu, d), by_bits(0xFFFFFFFFu, d));
}

/// Keys as a path tracer's wave holds them: fields of an array of structures.
struct Key {
  std::uint32_t other;
  std::uint32_t seed;
  std::uint32_t index;
};

TEST(Sampler, BatchedDimensionsAreTheScalarSamplersBitForBit) {
  std::mt19937 rng(20261128);
  for (const std::size_t count : {std::size_t(1), std::size_t(7), std::size_t(8), std::size_t(61)})
    for (const std::uint32_t dims : {0b0001u, 0b0111u, 0b1101u, 0b1111u})
      for (const bool simd : {false, true}) {
        std::vector<Key> keys(count);
        for (Key& k : keys) {
          k.other = rng();
          k.seed = PixelSampler(rng() % 204800u, rng() % 4u).stream_seed();
          // Small indices (the first frames), and any 32-bit one.
          k.index = rng() % 2 == 0 ? rng() % 64u : std::uint32_t(rng());
        }
        const std::uint32_t set = rng() % 30u;
        constexpr std::size_t kStride = 9; // two requests of 4 dimensions, and an untouched word
        std::vector<float> out(count * kStride, -1.0f);
        const std::array<detail::SampleRequest, 2> requests{
            detail::SampleRequest{set, dims, out.data()},
            detail::SampleRequest{set + 1, 0b1111u & ~dims, out.data() + 4}};
        detail::draw_sample_dims(detail::SampleKeys{&keys[0].seed, &keys[0].index, 3, count},
                                 requests, kStride, simd);
        for (std::size_t i = 0; i < count; ++i) {
          const PixelSampler sampler = PixelSampler::from_stream_seed(keys[i].seed);
          for (std::uint32_t d = 0; d < 8; ++d) {
            const std::uint32_t mask = d < 4 ? dims : 0b1111u & ~dims;
            const float expected = (mask >> d % 4 & 1u) != 0
                                       ? sampler.set(keys[i].index, set + d / 4).dim(d % 4)
                                       : -1.0f;
            ASSERT_EQ(std::bit_cast<std::uint32_t>(out[i * kStride + d]),
                      std::bit_cast<std::uint32_t>(expected))
                << "sample " << i << " of " << count << ", dimension " << d << ", simd " << simd;
          }
          ASSERT_EQ(out[i * kStride + 8], -1.0f) << "a word outside the dimensions was written";
        }
      }
}

TEST(Sampler, AStreamSeedGivesBackItsSampler) {
  for (const std::uint32_t pixel : {0u, 9u, 204799u})
    for (const std::uint32_t seed : {0u, 77u}) {
      const PixelSampler a(pixel, seed);
      const PixelSampler b = PixelSampler::from_stream_seed(a.stream_seed());
      for (std::uint32_t k = 0; k < 16; ++k) EXPECT_EQ(a.get4(k, 3), b.get4(k, 3));
    }
}

} // namespace
} // namespace specula

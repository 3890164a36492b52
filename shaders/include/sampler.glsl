// engine/trace/sampler.h on the device, bit for bit (integer maths only): Owen-scrambled,
// shuffled 4-D Sobol points by hashing, a seed per pixel, a set of 4 dimensions per use. The
// includer declares `uint sobol_tables[]`, sampler.h's kByteTables uploaded as is (4 × 4 × 256):
// four lookups per dimension, as the CPU, instead of a 32-step loop that would draw on lavapipe's
// per-dispatch loop budget.
#ifndef SPECULA_SAMPLER_GLSL
#define SPECULA_SAMPLER_GLSL

#include "include/hash.glsl"

uint owen_scramble(uint x, uint seed) {
  x = bitfieldReverse(x);
  x ^= x * 0x3d20adeau;
  x += seed;
  x *= (seed >> 16) | 1u;
  x ^= x * 0x05526c56u;
  x ^= x * 0x53a22864u;
  return bitfieldReverse(x);
}

uint sobol_u32(uint index, uint d) {
  uint t = d * 1024u;
  return sobol_tables[t + (index & 0xFFu)] ^ sobol_tables[t + 256u + ((index >> 8) & 0xFFu)] ^
         sobol_tables[t + 512u + ((index >> 16) & 0xFFu)] ^ sobol_tables[t + 768u + (index >> 24)];
}

float to_unit_float(uint x) { return float(x >> 8) * (1.0 / 16777216.0); }

// PixelSampler(stream, seed)'s seed.
uint pixel_seed(uint stream, uint seed) { return hash_combine(hash_u32(seed), stream); }

// PixelSampler::set(index, set): the set's seed and the shuffled index.
uvec2 sample_set(uint pixel, uint index, uint set) {
  uint set_seed = hash_combine(pixel, set);
  return uvec2(set_seed, owen_scramble(index, set_seed));
}

// SampleSet::dim(d) as the 32-bit fraction, and as the float.
uint sample_bits(uvec2 s, uint d) {
  return owen_scramble(sobol_u32(s.y, d), hash_combine(s.x, d + 1u));
}
float sample_dim(uvec2 s, uint d) { return to_unit_float(sample_bits(s, d)); }

#endif

// Included first by every kernel, after `#version 460` and
// `#extension GL_GOOGLE_include_directive : require`: the extensions Specula's GLSL uses.
#ifndef SPECULA_COMMON_GLSL
#define SPECULA_COMMON_GLSL
#extension GL_EXT_scalar_block_layout : enable
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : enable
#extension GL_KHR_shader_subgroup_basic : enable
#extension GL_KHR_shader_subgroup_vote : enable
#extension GL_KHR_shader_subgroup_arithmetic : enable
// Every floating-point operation of every kernel rounds on its own, as in the C++ build (which
// never fuses a multiply and an add): the build decorates each such SPIR-V instruction
// NoContraction (shaders/tools/spv_exact.cpp), so no kernel uses GLSL's `precise`.
#endif

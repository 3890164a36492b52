#pragma once
/// \file
/// SPECULA_ASSERT: the one assertion macro, for bugs (never for bad input, which throws
/// specula::Error). Active unless NDEBUG; define SPECULA_ASSERT_HANDLER(expr, file, line) before
/// including to override the reaction (tests use it to turn failures into exceptions).

#include <cstdio>
#include <cstdlib>

#ifndef SPECULA_ASSERT_HANDLER
#define SPECULA_ASSERT_HANDLER(expr, file, line)                                                   \
  (std::fprintf(stderr, "%s:%d: assertion failed: %s\n", file, line, expr), std::abort())
#endif

#ifdef NDEBUG
#define SPECULA_ASSERT(cond) static_cast<void>(0)
#else
#define SPECULA_ASSERT(cond)                                                                       \
  ((cond) ? static_cast<void>(0) : static_cast<void>(SPECULA_ASSERT_HANDLER(#cond, __FILE__, __LINE__)))
#endif

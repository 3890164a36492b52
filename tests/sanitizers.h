#pragma once
/// \file
/// SPECULA_TEST_ASAN is defined in AddressSanitizer builds, for tests that scale their work down
/// there (an exhaustive check strided, a soak shortened). GCC defines __SANITIZE_ADDRESS__ under
/// -fsanitize=address; Clang answers __has_feature.

#if defined(__SANITIZE_ADDRESS__)
#define SPECULA_TEST_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define SPECULA_TEST_ASAN 1
#endif
#endif

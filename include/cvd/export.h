// CVD_API marks the public symbols of libcvd. The shared library is built with
// -fvisibility=hidden, so only what carries CVD_API (and the cvd::Error type) is exported.
#pragma once

#if defined(_WIN32)
#define CVD_API
#else
#define CVD_API __attribute__((visibility("default")))
#endif

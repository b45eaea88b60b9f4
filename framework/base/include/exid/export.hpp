// exid — what libexid_dynamics and libexid_core export. Their code is compiled with hidden
// visibility (-fvisibility=hidden, as the plugins are): a symbol leaves the library only when its
// declaration says EXID_API. Every declaration of the installed headers does, and so do the
// entry points the exid program and the Python module use (declared in the layers' internal/
// headers, not installed); the report, the plots and the other helpers beside a layer's sources
// stay inside. Only ELF's visibility is meant: nothing to import on this platform.
#pragma once

#if defined(__GNUC__) || defined(__clang__)
#define EXID_API __attribute__((visibility("default")))
#else
#define EXID_API
#endif

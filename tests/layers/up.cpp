// A file of the `data` layer that includes a header of the `study` layer above it: it must not
// compile (tests/layers/check_layers.cmake).
#include "exid/runner.hpp"

int exidLayerProbeUp() { return 0; }

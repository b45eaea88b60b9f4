// A file of the `data` layer that includes headers of its own layer and of `base` below it: it
// must compile (tests/layers/check_layers.cmake), so that the upward probe fails for its include.
#include "exid/error.hpp"
#include "exid/json.hpp"
#include "exid/signal.hpp"

int exidLayerProbeDown() { return 0; }

// exid 0.3: forwarding header, for one release. exid/inspect.hpp belonged to the core's
// inspection, which 0.3 no longer installs; its recording statistics (samplingStats,
// rateFromPeriod), which experiments use, are the data layer's exid/recording_stats.hpp
// (docs/architecture.md, "Public and internal"). Removed in 0.4.
#pragma once
#pragma message( \
    "exid/inspect.hpp is no longer part of exid's installed API: include exid/recording_stats.hpp (samplingStats, rateFromPeriod); this forwarding header goes in exid 0.4")

#include "exid/recording_stats.hpp"
#include "exid/signal.hpp"

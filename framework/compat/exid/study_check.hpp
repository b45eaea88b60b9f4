// exid 0.3: forwarding header, for one release. exid/study_check.hpp belonged to the core's study
// and matrix, which 0.3 no longer installs; a program runs studies and matrices through the
// embedding facade, exid/exid.hpp (docs/architecture.md, "Public and internal"). Removed in 0.4.
#pragma once
#pragma message( \
    "exid/study_check.hpp is no longer part of exid's installed API: include exid/exid.hpp (runStudyFile, runMatrixFile); this forwarding header goes in exid 0.4")

#include "exid/exid.hpp"

// exid — several observation models stacked into one (a study's list of models; private to the
// study layer).
#pragma once

#include <memory>
#include <vector>

#include "exid/interfaces.hpp"

namespace exid {

/// Several observation models stacked into one (e.g. differential + load_wrench). Columns are
/// the union of the models' full columns (matched by name); each block's rows (and
/// measurements) are multiplied by its weight.
std::shared_ptr<ObservationModel> makeStackedModel(
    std::vector<std::shared_ptr<ObservationModel>> parts, std::vector<double> weights);

}  // namespace exid

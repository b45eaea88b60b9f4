// exid — rosbag2: what the reader's own files share beyond bag.hpp (not installed, not for
// the plugin or the tests).
#pragma once

#include <filesystem>
#include <functional>
#include <set>
#include <string>

#include "bag.hpp"

namespace exid::rosbag2::detail {

/// The MCAP part of readMessages: one storage file read whole (at most kMaxMcapFileBytes), then
/// readMcapBytes (bag_mcap.cpp).
void readMcap(const BagInfo& bag, const std::filesystem::path& path,
              const std::set<std::string>& wanted, const std::function<void(const RawMessage&)>& fn,
              Census* census);

}  // namespace exid::rosbag2::detail

/**
 * \file unset.h
 * \brief The value of a tunable that no one set: option structs start with it, so that a value the YAML did not give
 *        is an error at create() rather than a second default.
 */
#pragma once

#include <limits>

namespace moverl_planning_scene {

constexpr double kUnset = std::numeric_limits<double>::quiet_NaN();

}  // namespace moverl_planning_scene

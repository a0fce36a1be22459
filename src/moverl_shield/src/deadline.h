// Deadlines of the shield's calls (ROS part of the shield node). ROS 1 calls have none of their own: roscpp service
// calls block until the server answers or its connection drops. The shield's service calls go over moverl_tcpros,
// whose connects, reads and writes end at a deadline; the FollowJointTrajectory driver waits for its results with one.
// Deadlines run on the steady (wall) clock: a stalled simulator also stops /clock, and sim-time deadlines would never
// pass.
#pragma once

#include <chrono>

#include "moverl_shield/driver_core.h"
#include "moverl_tcpros/call_end.h"

namespace moverl_shield {

using moverl_tcpros::after;        // the steady-clock time so many seconds from now
using moverl_tcpros::SteadyClock;  // the clock of every deadline

/// \brief Wall-clock seconds since the epoch: the `not_after` of requests, comparable across processes on one host.
inline double wallSeconds() {
  return std::chrono::duration<double>(std::chrono::system_clock::now().time_since_epoch()).count();
}

/// \brief True when a request's `not_after` (wall seconds, 0: none) has passed: its caller gave up on it.
inline bool abandoned(double not_after) { return not_after > 0.0 && wallSeconds() > not_after; }

}  // namespace moverl_shield

// How a call with a deadline ends, and the clock its deadlines run on. No ROS headers here: the shield's ROS-free core
// (moverl_shield/driver_core.h) maps these ends to its verdicts.
#pragma once

#include <chrono>

namespace moverl_tcpros {

/// Deadlines run on the steady (wall) clock: a stalled simulator also stops /clock, and sim-time deadlines would never
/// pass.
using SteadyClock = std::chrono::steady_clock;

/// \brief The steady-clock time `seconds` from now.
inline SteadyClock::time_point after(double seconds) {
  return SteadyClock::now() + std::chrono::duration_cast<SteadyClock::duration>(std::chrono::duration<double>(seconds));
}

/// \brief How a call with a deadline ended. A request is sent at most once: kUnreachable says that the server never got
///        it; after kTimedOut, kClosed and kFailed it may have acted on it (a move may have been made).
enum class CallEnd {
  kAnswered,     ///< the server answered
  kUnreachable,  ///< the request was not delivered: not advertised, no connection, or refused at the header
  kTimedOut,     ///< the deadline passed (the connection was dropped: a late answer is never read as another's)
  kClosed,       ///< the connection closed after the request was written, before the whole answer arrived
  kFailed,       ///< the server answered with an error (its handler failed) or with bytes that are no answer
};

/// \brief "answered", "unreachable", "timed out", "closed while the answer was awaited", "failed".
inline const char* callEndName(CallEnd end) {
  switch (end) {
    case CallEnd::kAnswered:
      return "answered";
    case CallEnd::kUnreachable:
      return "unreachable";
    case CallEnd::kTimedOut:
      return "timed out";
    case CallEnd::kClosed:
      return "closed while the answer was awaited";
    case CallEnd::kFailed:
      return "failed";
  }
  return "unknown";
}

}  // namespace moverl_tcpros

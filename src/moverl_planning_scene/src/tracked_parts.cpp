#include "moverl_planning_scene/tracked_parts.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>
#include <stdexcept>

namespace moverl_planning_scene {

namespace {

bool finiteNonNegative(double x) { return std::isfinite(x) && x >= 0.0; }

}  // namespace

std::string PartMotionBound::problem() const {
  if (!finiteNonNegative(max_acceleration)) return "max_acceleration must be a finite number >= 0 (m/s^2)";
  if (!(std::isfinite(max_speed) && max_speed > 0.0)) return "max_speed must be a finite number > 0 (m/s)";
  return "";
}

double PartMotionBound::travel(double speed, double t) const {
  const double cap = std::max(max_speed, speed);
  const double t_cap = max_acceleration > 0.0 ? (cap - speed) / max_acceleration : 0.0;
  if (t <= t_cap) return speed * t + 0.5 * max_acceleration * t * t;
  return speed * t_cap + 0.5 * max_acceleration * t_cap * t_cap + cap * (t - t_cap);
}

std::string TrackingRule::problem() const {
  const std::string bad = motion.problem();
  if (!bad.empty()) return bad;
  if (!finiteNonNegative(position_error)) return "position_error must be a finite number >= 0 (m)";
  if (!finiteNonNegative(speed_error)) return "speed_error must be a finite number >= 0 (m/s)";
  if (!finiteNonNegative(max_age)) return "max_age must be a finite number >= 0 (s)";
  return "";
}

std::vector<ExplainedPart> explainParts(const std::vector<TrackedPart>& parts, const TrackingRule& rule, double now,
                                        double map_time, double end, double iso_margin, double uncertainty) {
  const std::string bad = rule.problem();
  if (!bad.empty()) throw std::invalid_argument("tracking: " + bad);
  if (!std::isfinite(now) || !std::isfinite(map_time) || !std::isfinite(end) || !std::isfinite(iso_margin) ||
      !finiteNonNegative(uncertainty)) {
    throw std::invalid_argument("tracking: the check's times, its margin and Z_d must be finite (Z_d >= 0)");
  }
  std::vector<ExplainedPart> out;
  for (const TrackedPart& p : parts) {
    // Lost: too old, from the future (a clock the checks do not share), or not a number.
    if (!(p.stamp <= now && now - p.stamp <= rule.max_age)) continue;
    if (!p.position.allFinite() || !finiteNonNegative(p.speed) || !finiteNonNegative(p.radius)) continue;
    const double speed = p.speed + rule.speed_error;
    const double around = p.radius + rule.position_error;
    // Where the part was when the map saw its cells (before or after the measurement: the same bound either way), and
    // where it may be by the window's end.
    const double keep_out = around + uncertainty + rule.motion.travel(speed, std::max(0.0, end - p.stamp));
    const double explains = std::min(keep_out, around + rule.motion.travel(speed, std::fabs(map_time - p.stamp)));
    // Its ball holds every explained cell grown by ISO's margin: the intersection is ISO's margin alone.
    if (!(keep_out < explains + iso_margin)) continue;
    out.push_back(ExplainedPart{p.id, p.position, explains, keep_out});
  }
  return out;
}

bool parsePartRadii(const std::string& text, std::vector<std::pair<std::string, double>>* out, std::string* error) {
  out->clear();
  std::stringstream entries(text);
  std::string entry;
  while (std::getline(entries, entry, ',')) {
    std::istringstream in(entry);
    std::string frame, rest;
    double radius = 0.0;
    const bool named = static_cast<bool>(in >> frame);
    const bool sized = named && static_cast<bool>(in >> radius);
    if (!named && out->empty() && entries.eof()) break;  // "" lists nothing
    bool good = sized && !(in >> rest) && std::isfinite(radius) && radius >= 0.0;
    for (char c : frame) good = good && (std::isalnum(static_cast<unsigned char>(c)) || c == '_');
    for (const auto& p : *out) good = good && p.first != frame;
    if (!good) {
      *error =
          "'" + entry + "': expected \"<frame> <radius>\" (a frame of letters, digits and _, once; a radius >= 0 m)";
      return false;
    }
    out->emplace_back(frame, radius);
  }
  return true;
}

}  // namespace moverl_planning_scene

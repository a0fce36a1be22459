/**
 * \file failsafe_stop.cpp
 * \brief ROS-free command-line view of the shield's failsafe stop model (failsafe.h), for the test that measures it
 *        against the dynamic simulator's motors (test/test_failsafe_stop.py) and for anyone who wants the numbers.
 *
 *   failsafe_stop --velocity v1,...,vn --deceleration a1,...,an [--reaction T] [--sample-period DT]
 *
 * Then one state per line on stdin, "q1 ... qn v1 ... vn"; per state on stdout:
 *   bound T_r t_b lower1 ... lowern upper1 ... uppern
 *   trajectory K                                    (the braking trajectory from the state, K points; then K lines)
 *   t p1 ... pn v1 ... vn a1 ... an
 * A bad line gives "error <message>" (the program goes on). Exit code 2 on bad arguments.
 */
#include <iomanip>
#include <iostream>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "moverl_shield/failsafe.h"

namespace {

std::vector<double> parseList(const std::string& text) {
  std::vector<double> out;
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) out.push_back(std::stod(item));
  return out;
}

void usage() {
  std::cerr << "usage: failsafe_stop --velocity v1,...,vn --deceleration a1,...,an [--reaction T] "
               "[--sample-period DT]\n";
}

}  // namespace

int main(int argc, char** argv) {
  using namespace moverl_shield;
  StopLimits limits;
  double period = 0.01;
  try {
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      const std::string value = argv[++i];
      if (a == "--velocity") {
        limits.velocity = parseList(value);
      } else if (a == "--deceleration") {
        limits.deceleration = parseList(value);
      } else if (a == "--reaction") {
        limits.reaction_time = std::stod(value);
      } else if (a == "--sample-period") {
        period = std::stod(value);
      } else {
        throw std::invalid_argument("unknown argument " + a +
                                    " (valid: --velocity, --deceleration, --reaction, --sample-period)");
      }
    }
    if (limits.velocity.empty() || limits.velocity.size() != limits.deceleration.size()) {
      throw std::invalid_argument("--velocity and --deceleration need one value per joint each");
    }
  } catch (const std::exception& e) {
    std::cerr << "failsafe_stop: " << e.what() << "\n";
    usage();
    return 2;
  }
  const std::size_t n = limits.velocity.size();
  std::cout << std::setprecision(17);
  std::string line;
  while (std::getline(std::cin, line)) {
    std::stringstream ss(line);
    std::vector<double> values;
    double x;
    while (ss >> x) values.push_back(x);
    try {
      if (values.size() != 2 * n) {
        throw std::invalid_argument("a state is " + std::to_string(2 * n) + " numbers (q then v), got " +
                                    std::to_string(values.size()));
      }
      const std::vector<double> q(values.begin(), values.begin() + n), v(values.begin() + n, values.end());
      const StopBound b = failsafeStop(q, v, limits);
      const TimedTrajectory t = brakingTrajectory(q, v, limits, period);
      std::cout << "bound " << b.reaction_time << " " << b.braking_time;
      for (double y : b.lower) std::cout << " " << y;
      for (double y : b.upper) std::cout << " " << y;
      std::cout << "\ntrajectory " << t.times.size() << "\n";
      for (std::size_t k = 0; k < t.times.size(); ++k) {
        std::cout << t.times[k];
        for (const auto* row : {&t.positions[k], &t.velocities[k], &t.accelerations[k]}) {
          for (double y : *row) std::cout << " " << y;
        }
        std::cout << "\n";
      }
    } catch (const std::exception& e) {
      std::cout << "error " << e.what() << "\n";
    }
    std::cout << std::flush;
  }
  return 0;
}

/**
 * \file test_pending_clouds.cpp
 * \brief pending_clouds.h without a roscore: what a camera's queue keeps in lockstep and in real time (admitCloud), and
 *        which instant the integrator takes whole in real time (newestWholeInstant, dropOlderThan).
 */
#include <gtest/gtest.h>

#include <cmath>
#include <deque>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "moverl_planning_scene/pending_clouds.h"

namespace mps = moverl_planning_scene;

namespace {

struct Cloud {
  double stamp;
};
constexpr double kNone = std::numeric_limits<double>::quiet_NaN();

std::vector<double> stamps(const std::deque<Cloud>& q) {
  std::vector<double> out;
  for (const Cloud& c : q) out.push_back(c.stamp);
  return out;
}

std::size_t admit(std::deque<Cloud>* q, double stamp, bool lockstep, double batch = kNone, double flight = kNone) {
  return mps::admitCloud(q, Cloud{stamp}, [](const Cloud& c) { return c.stamp; }, lockstep, 3, batch, flight);
}

}  // namespace

TEST(PendingClouds, LockstepKeepsEveryViewInOrderUpToItsDepth) {
  std::deque<Cloud> q;
  EXPECT_EQ(admit(&q, 1.0, true), 0u);
  EXPECT_EQ(admit(&q, 2.0, true), 0u);
  EXPECT_EQ(admit(&q, 3.0, true), 0u);
  EXPECT_EQ(admit(&q, 4.0, true, 1.0, 1.0), 1u);  // full: the oldest goes, whatever the batch
  EXPECT_EQ(stamps(q), (std::vector<double>{2.0, 3.0, 4.0}));
}

TEST(PendingClouds, RealTimeKeepsTheTwoNewest) {
  std::deque<Cloud> q;
  EXPECT_EQ(admit(&q, 1.0, false), 0u);
  EXPECT_EQ(admit(&q, 2.0, false, 0.5), 0u);
  EXPECT_EQ(admit(&q, 3.0, false, 0.5), 1u);  // another batch is open: the oldest, 1.0, goes
  EXPECT_EQ(stamps(q), (std::vector<double>{2.0, 3.0}));
}

TEST(PendingClouds, RealTimeKeepsACloudOfTheBatchBeingIntegrated) {
  // 1.0 is the open batch's (or the cloud in flight's) instant: it stays, and newer ones replace each other behind it.
  for (const bool open : {true, false}) {
    std::deque<Cloud> q;
    admit(&q, 1.0, false);
    const double batch = open ? 1.0 : kNone, flight = open ? kNone : 1.0;
    EXPECT_EQ(admit(&q, 2.0, false, batch, flight), 0u);
    EXPECT_EQ(admit(&q, 3.0, false, batch, flight), 1u);
    EXPECT_EQ(stamps(q), (std::vector<double>{1.0, 3.0}));
    // Once it is integrated (popped by the integrator) the two newest stay again.
    q.pop_front();
    EXPECT_EQ(admit(&q, 4.0, false, 3.5), 0u);
    EXPECT_EQ(admit(&q, 5.0, false, 3.5), 1u);
    EXPECT_EQ(stamps(q), (std::vector<double>{4.0, 5.0}));
  }
}

namespace {

using Queues = std::map<std::string, std::deque<Cloud>>;

double whole(const Queues& pending, const std::vector<std::string>& expected) {
  return mps::newestWholeInstant(pending, expected, [](const Cloud& c) { return c.stamp; });
}

}  // namespace

TEST(PendingClouds, TheNextBatchIsTheNewestInstantEveryExpectedCameraHas) {
  // The integrator comes free while the next instant (2.0) is on its way: a and b have sent it, c not yet. 1.0 is the
  // newest instant all three have; 2.0 would make a batch without c.
  Queues pending{{"a", {{1.0}, {2.0}}}, {"b", {{1.0}, {2.0}}}, {"c", {{1.0}}}};
  EXPECT_EQ(whole(pending, {"a", "b", "c"}), 1.0);
  pending["c"].push_back({2.0});
  EXPECT_EQ(whole(pending, {"a", "b", "c"}), 2.0);
  // A camera not expected (not heard lately) does not hold the others back.
  EXPECT_EQ(whole(Queues{{"a", {{2.0}}}, {"b", {{2.0}}}}, {"a", "b"}), 2.0);
}

TEST(PendingClouds, NoWholeInstantWhenAnExpectedCameraHasNone) {
  EXPECT_TRUE(std::isnan(whole(Queues{{"a", {{1.0}}}, {"b", {{2.0}}}}, {"a", "b"})));  // unsynchronised cameras
  EXPECT_TRUE(std::isnan(whole(Queues{{"a", {{1.0}}}}, {"a", "b"})));                  // b sent nothing
  EXPECT_TRUE(std::isnan(whole(Queues{{"a", {{1.0}}}}, {})));                          // nothing expected
  EXPECT_TRUE(std::isnan(whole(Queues{}, {"a"})));
}

TEST(PendingClouds, DropOlderThanLeavesTheInstantAndNewerAndErasesEmptyQueues) {
  Queues pending{{"a", {{1.0}, {2.0}}}, {"b", {{2.0}, {3.0}}}, {"c", {{1.0}}}};
  EXPECT_EQ(mps::dropOlderThan(&pending, 2.0, [](const Cloud& c) { return c.stamp; }), 2u);
  ASSERT_EQ(pending.size(), 2u);
  EXPECT_EQ(stamps(pending["a"]), (std::vector<double>{2.0}));
  EXPECT_EQ(stamps(pending["b"]), (std::vector<double>{2.0, 3.0}));
}

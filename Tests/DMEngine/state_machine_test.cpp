// The life-cycle graph: every legal edge, every illegal one refused with a
// message naming the legal targets, observers and history in order.
#include <dm/engine/state_machine.hpp>

#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace dm {
namespace {

constexpr SimState kAll[] = {SimState::Created, SimState::Loading,  SimState::Ready,   SimState::Running,
                             SimState::Paused,  SimState::Stopping, SimState::Stopped, SimState::Error};

TEST(StateMachine, GraphMatchesTheDesign) {
  // The edges of the design's diagram, nothing else; Error from every state but Stopped and Error.
  const std::vector<std::pair<SimState, SimState>> edges = {
      {SimState::Created, SimState::Loading},  {SimState::Loading, SimState::Ready},
      {SimState::Ready, SimState::Running},    {SimState::Ready, SimState::Stopping},
      {SimState::Running, SimState::Paused},   {SimState::Paused, SimState::Running},
      {SimState::Running, SimState::Stopping}, {SimState::Paused, SimState::Stopping},
      {SimState::Stopping, SimState::Stopped}, {SimState::Error, SimState::Stopping}};
  for (SimState from : kAll)
    for (SimState to : kAll) {
      bool expected = to == SimState::Error ? (from != SimState::Stopped && from != SimState::Error) : false;
      for (const auto& e : edges) expected = expected || (e.first == from && e.second == to);
      EXPECT_EQ(isLegalTransition(from, to), expected) << toString(from) << " -> " << toString(to);
    }
}

TEST(StateMachine, IllegalTransitionIsRefusedAndNamed) {
  StateMachine fsm;
  ASSERT_TRUE(fsm.transition(SimState::Loading).ok());
  const Status s = fsm.transition(SimState::Running);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.error().what, "illegal transition loading -> running");
  EXPECT_EQ(s.error().hint, "from loading: ready, error");
  EXPECT_EQ(fsm.state(), SimState::Loading);
}

TEST(StateMachine, ObserversSeeEveryTransitionInOrder) {
  StateMachine fsm;
  std::vector<std::string> seen;
  fsm.onTransition(
      [&](const Transition& t) { seen.push_back(std::string(toString(t.from)) + ">" + toString(t.to)); });
  ASSERT_TRUE(fsm.transition(SimState::Loading, "scene.json").ok());
  ASSERT_TRUE(fsm.transition(SimState::Ready).ok());
  ASSERT_TRUE(fsm.transition(SimState::Running).ok());
  ASSERT_TRUE(fsm.transition(SimState::Error, "device lost").ok());
  ASSERT_TRUE(fsm.transition(SimState::Stopping).ok());
  ASSERT_TRUE(fsm.transition(SimState::Stopped).ok());
  EXPECT_FALSE(fsm.transition(SimState::Error).ok());  // nothing leaves Stopped
  const std::vector<std::string> expected = {"created>loading", "loading>ready",  "ready>running",
                                             "running>error",   "error>stopping", "stopping>stopped"};
  EXPECT_EQ(seen, expected);
  ASSERT_EQ(fsm.history().size(), 6u);
  EXPECT_EQ(fsm.history()[0].reason, "scene.json");
  EXPECT_EQ(fsm.history()[3].reason, "device lost");
}

}  // namespace
}  // namespace dm

// Tests for the ECS rules of docs/ecs.md, one group per rule. Each test asserts the property the
// rule names; the randomized tests compare against a plain std::map model with a fixed seed.

#include "specula/ecs/registry.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdint>
#include <map>
#include <optional>
#include <ostream>
#include <random>
#include <set>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

// gtest prints handles in failure messages through this (found by ADL).
namespace specula::ecs {
void PrintTo(Entity e, std::ostream* os);
void PrintTo(Entity e, std::ostream* os) {
  *os << "Entity{" << e.index << ", " << e.generation << "}";
}
} // namespace specula::ecs

namespace {

using specula::ecs::Entity;
using specula::ecs::null_entity;
using specula::ecs::Registry;

struct Position {
  float x = 0.0f;
  float y = 0.0f;
};
struct Velocity {
  float dx = 0.0f;
};
struct Tag {};

/// Counts its live instances through a counter the test owns (no globals): every constructor
/// increments, the destructor decrements, so a leak or a double destruction shows as a mismatch.
class Counted {
public:
  explicit Counted(int* live, int value = 0) : live_(live), value_(value) { ++*live_; }
  Counted(const Counted& o) : live_(o.live_), value_(o.value_) { ++*live_; }
  Counted(Counted&& o) noexcept : live_(o.live_), value_(o.value_) { ++*live_; }
  Counted& operator=(const Counted&) = default;
  Counted& operator=(Counted&&) noexcept = default;
  ~Counted() { --*live_; }
  [[nodiscard]] int value() const { return value_; }

private:
  int* live_;
  int value_;
};

/// Its constructor throws when asked to, to test that a failed emplace leaves no trace.
struct ThrowsOnConstruct {
  explicit ThrowsOnConstruct(bool fail) {
    if (fail) throw std::runtime_error("construction failed");
  }
};

struct EntityLess {
  bool operator()(Entity a, Entity b) const {
    return std::pair(a.index, a.generation) < std::pair(b.index, b.generation);
  }
};
using EntitySet = std::set<Entity, EntityLess>;

// --- Rule 1: handles ------------------------------------------------------------------------

TEST(EcsHandles, DestroyMakesEveryCopyOfTheHandleStale) {
  Registry reg;
  const Entity e = reg.create();
  const Entity copy = e;
  reg.emplace<Position>(e, 1.0f, 2.0f);
  reg.emplace<Tag>(e);
  ASSERT_TRUE(reg.valid(copy));

  reg.destroy(e);

  EXPECT_FALSE(reg.valid(copy));
  EXPECT_FALSE(reg.has<Position>(copy));
  EXPECT_FALSE(reg.has<Tag>(copy));
  EXPECT_EQ(reg.try_get<Position>(copy), nullptr);
  EXPECT_EQ(std::as_const(reg).try_get<Position>(copy), nullptr);
  EXPECT_FALSE(reg.remove<Position>(copy));
  EXPECT_EQ(reg.count<Position>(), 0u);
  EXPECT_EQ(reg.alive(), 0u);
  reg.destroy(copy); // a stale destroy is a no-op...
  EXPECT_EQ(reg.alive(), 0u);
  const Entity next = reg.create();
  reg.destroy(copy); // ...even once the slot is reused
  EXPECT_TRUE(reg.valid(next));
  EXPECT_EQ(reg.alive(), 1u);
}

TEST(EcsHandles, RecycledSlotGetsNewGenerationAndOldHandleStaysStale) {
  Registry reg;
  const Entity old = reg.create();
  reg.emplace<Position>(old, 5.0f, 6.0f);
  reg.destroy(old);

  const Entity fresh = reg.create();
  EXPECT_EQ(fresh.index, old.index); // the slot is reused...
  EXPECT_NE(fresh.generation, old.generation);
  EXPECT_NE(fresh, old);
  EXPECT_TRUE(reg.valid(fresh));
  EXPECT_FALSE(reg.valid(old)); // ...but the old handle does not come back to life
  EXPECT_FALSE(reg.has<Position>(fresh)) << "a recycled slot starts without components";

  reg.emplace<Position>(fresh, 7.0f, 8.0f);
  EXPECT_FALSE(reg.has<Position>(old));
  EXPECT_EQ(reg.try_get<Position>(old), nullptr);
  EXPECT_FALSE(reg.remove<Position>(old));
  EXPECT_TRUE(reg.has<Position>(fresh)) << "a stale remove must not touch the slot's new owner";
  reg.destroy(old);
  EXPECT_TRUE(reg.valid(fresh)) << "a stale destroy must not touch the slot's new owner";
}

TEST(EcsHandles, RepeatedRecyclingNeverRevivesAnyOldHandle) {
  Registry reg;
  std::vector<Entity> history;
  Entity e = reg.create();
  for (int i = 0; i < 1000; ++i) {
    history.push_back(e);
    reg.destroy(e);
    e = reg.create();
  }
  EXPECT_TRUE(reg.valid(e));
  for (const Entity old : history) {
    EXPECT_EQ(old.index, e.index);
    EXPECT_FALSE(reg.valid(old));
    EXPECT_NE(old, e);
  }
}

TEST(EcsHandles, ClearMakesEveryHandleStaleAndNewHandlesDiffer) {
  Registry reg;
  std::vector<Entity> before;
  for (int i = 0; i < 10; ++i) before.push_back(reg.create());
  reg.emplace<Position>(before[3]);

  reg.clear();
  EXPECT_EQ(reg.alive(), 0u);
  EXPECT_EQ(reg.count<Position>(), 0u);
  for (const Entity e : before) EXPECT_FALSE(reg.valid(e));

  for (int i = 0; i < 20; ++i) {
    const Entity e = reg.create();
    EXPECT_EQ(std::count(before.begin(), before.end(), e), 0) << "clear() must not recycle handles";
  }
  for (const Entity e : before) EXPECT_FALSE(reg.valid(e));
}

TEST(EcsHandles, NullEntityIsNeverValid) {
  Registry reg;
  EXPECT_TRUE(null_entity.is_null());
  EXPECT_FALSE(reg.valid(null_entity));
  for (int i = 0; i < 4; ++i) static_cast<void>(reg.create());
  EXPECT_FALSE(reg.valid(null_entity));
  EXPECT_FALSE(reg.has<Position>(null_entity));
  EXPECT_EQ(reg.try_get<Position>(null_entity), nullptr);
  EXPECT_EQ(Entity{}, null_entity) << "a default handle is the null handle";
}

TEST(EcsHandles, EachEntityVisitsLiveEntitiesOnceEvenWhileChangingThem) {
  Registry reg;
  std::vector<Entity> all;
  for (int i = 0; i < 50; ++i) all.push_back(reg.create());
  for (int i = 0; i < 50; i += 5) reg.destroy(all[std::size_t(i)]);

  // f destroys the next slot's entity and creates new ones: neither may be visited.
  EntitySet visited;
  EntitySet destroyed_in_walk;
  EntitySet created_in_walk;
  reg.each_entity([&](Entity e) {
    EXPECT_TRUE(reg.valid(e));
    EXPECT_TRUE(visited.insert(e).second) << "visited twice";
    EXPECT_EQ(destroyed_in_walk.count(e), 0u);
    EXPECT_EQ(created_in_walk.count(e), 0u);
    const Entity next{e.index + 1, e.generation};
    if (e.index % 7 == 0 && next.index < all.size() && reg.valid(next)) {
      reg.destroy(next);
      destroyed_in_walk.insert(next);
    }
    created_in_walk.insert(reg.create());
  });
  for (std::size_t i = 0; i < all.size(); ++i) {
    const bool expected = i % 5 != 0 && destroyed_in_walk.count(all[i]) == 0;
    EXPECT_EQ(visited.count(all[i]), expected ? 1u : 0u) << "entity " << i;
  }
  EXPECT_EQ(visited.size() + destroyed_in_walk.size(), 40u);
}

#ifndef NDEBUG
// Using a stale handle for get/emplace is a bug, caught by SPECULA_ASSERT in builds with asserts.
TEST(EcsHandlesDeathTest, EmplaceOrGetOnStaleHandleAsserts) {
  Registry reg;
  const Entity e = reg.create();
  reg.destroy(e);
  EXPECT_DEATH(reg.emplace<Position>(e), "assertion failed");
  EXPECT_DEATH(reg.emplace_or_replace<Position>(e), "assertion failed");
  EXPECT_DEATH(static_cast<void>(reg.get<Position>(e)), "assertion failed");
  EXPECT_DEATH(reg.emplace<Position>(null_entity), "assertion failed");
}

TEST(EcsHandlesDeathTest, EmplacingTwiceOrGettingAMissingComponentAsserts) {
  Registry reg;
  const Entity e = reg.create();
  reg.emplace<Position>(e);
  EXPECT_DEATH(reg.emplace<Position>(e), "assertion failed");
  EXPECT_DEATH(static_cast<void>(reg.get<Velocity>(e)), "assertion failed");
  EXPECT_DEATH(static_cast<void>(reg.resource<Velocity>()), "assertion failed");
}
#endif

// --- Sparse sets: membership and values under swap-and-pop ----------------------------------

TEST(EcsStorage, MembershipIsExactAfterSwapAndPopRemovals) {
  Registry reg;
  std::vector<Entity> es;
  for (int i = 0; i < 300; ++i) {
    es.push_back(reg.create());
    reg.emplace<Position>(es.back(), float(i), float(-i));
  }
  // Remove in a shuffled order (seeded) so holes appear everywhere, including at the end.
  std::vector<std::size_t> order(es.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(20240611u);
  std::shuffle(order.begin(), order.end(), rng);
  std::vector<bool> removed(es.size(), false);
  for (std::size_t k = 0; k < order.size() / 2; ++k) {
    const std::size_t i = order[k];
    EXPECT_TRUE(reg.remove<Position>(es[i]));
    EXPECT_FALSE(reg.remove<Position>(es[i])) << "second removal must report nothing removed";
    removed[i] = true;
  }
  std::size_t expected_count = 0;
  for (std::size_t i = 0; i < es.size(); ++i) {
    EXPECT_EQ(reg.has<Position>(es[i]), !removed[i]) << "entity " << i;
    EXPECT_TRUE(reg.valid(es[i])) << "removing a component must not destroy the entity";
    if (!removed[i]) {
      ++expected_count;
      ASSERT_NE(reg.try_get<Position>(es[i]), nullptr);
      EXPECT_EQ(reg.get<Position>(es[i]).x, float(i)) << "value of entity " << i << " changed";
      EXPECT_EQ(reg.get<Position>(es[i]).y, -float(i));
    }
  }
  EXPECT_EQ(reg.count<Position>(), expected_count);
  EXPECT_EQ(reg.view<Position>().size(), expected_count);
}

TEST(EcsStorage, MovedElementKeepsItsValueAndOwner) {
  Registry reg;
  std::vector<Entity> es;
  for (int i = 0; i < 10; ++i) {
    es.push_back(reg.create());
    reg.emplace<std::string>(es.back(), "entity " + std::to_string(i));
  }
  // The first-added is not the pool's last, so removing it swaps the last one into its place.
  const std::string* last_before = &reg.get<std::string>(es.back());
  reg.remove<std::string>(es.front());
  EXPECT_NE(&reg.get<std::string>(es.back()), last_before) << "the test expects a swap";
  for (std::size_t i = 1; i < es.size(); ++i)
    EXPECT_EQ(reg.get<std::string>(es[i]), "entity " + std::to_string(i));
  // Destroying an entity removes its components the same way.
  reg.destroy(es[4]);
  for (std::size_t i = 1; i < es.size(); ++i)
    if (i != 4) {
      EXPECT_EQ(reg.get<std::string>(es[i]), "entity " + std::to_string(i));
    }
}

TEST(EcsStorage, RemovalMovesAtMostTheLastElementOfThatType) {
  Registry reg;
  std::vector<Entity> es;
  for (int i = 0; i < 600; ++i) { // more than two pages
    es.push_back(reg.create());
    reg.emplace<Position>(es.back(), float(i));
    reg.emplace<Velocity>(es.back(), float(i));
  }
  std::mt19937 rng(7u);
  std::vector<bool> gone(es.size(), false);
  for (int round = 0; round < 200; ++round) {
    std::map<std::size_t, const Position*> before;
    std::map<std::size_t, const Velocity*> velocity_before;
    for (std::size_t i = 0; i < es.size(); ++i)
      if (!gone[i]) {
        before[i] = &reg.get<Position>(es[i]);
        velocity_before[i] = &reg.get<Velocity>(es[i]);
      }
    std::size_t victim = 0;
    do victim = std::uniform_int_distribution<std::size_t>(0, es.size() - 1)(rng);
    while (gone[victim]);
    reg.remove<Position>(es[victim]);
    gone[victim] = true;

    int moved = 0;
    for (const auto& [i, p] : before)
      if (i != victim) {
        moved += &reg.get<Position>(es[i]) != p ? 1 : 0;
        EXPECT_EQ(reg.get<Position>(es[i]).x, float(i));
        EXPECT_EQ(&reg.get<Velocity>(es[i]), velocity_before[i]) << "other types never move";
      }
    EXPECT_LE(moved, 1) << "round " << round;
  }
}

// --- Rule 2: references stay valid across emplace --------------------------------------------

TEST(EcsStorage, ReferencesSurviveTenThousandEmplaces) {
  Registry reg;
  const Entity first = reg.create();
  Position& pos = reg.emplace<Position>(first, 3.0f, 4.0f);
  std::string& name = reg.emplace<std::string>(first, "first");
  const Position* pos_address = &pos;
  const std::string* name_address = &name;

  for (int i = 0; i < 10000; ++i) {
    const Entity e = reg.create();
    reg.emplace<Position>(e, float(i), 0.0f);
    reg.emplace<std::string>(e, std::to_string(i));
    if (i % 3 == 0) reg.emplace<Velocity>(e);
    reg.emplace_or_replace<Velocity>(e, float(i)); // replace and emplace paths both
  }
  EXPECT_EQ(&reg.get<Position>(first), pos_address);
  EXPECT_EQ(&reg.get<std::string>(first), name_address);
  EXPECT_EQ(pos.x, 3.0f); // the old references still read the right values
  EXPECT_EQ(pos.y, 4.0f);
  EXPECT_EQ(name, "first");
  pos.x = 9.0f; // and write through to the stored component
  EXPECT_EQ(reg.get<Position>(first).x, 9.0f);
}

TEST(EcsStorage, NonAggregateComponentsAreConstructedWithParentheses) {
  Registry reg;
  const Entity e = reg.create();
  // (3, 7) is three sevens, not the two-element list {3, 7}.
  const auto& v = reg.emplace<std::vector<int>>(e, 3u, 7);
  EXPECT_EQ(v, std::vector<int>(3u, 7));
  reg.emplace_or_replace<std::vector<int>>(e, 2u, 1);
  EXPECT_EQ(reg.get<std::vector<int>>(e), std::vector<int>(2u, 1));
  const auto& p = reg.emplace<Position>(e, 1.0f, 2.0f); // aggregates use braces
  EXPECT_EQ(p.y, 2.0f);
}

// --- Rule 3: views -----------------------------------------------------------------------------

/// A registry with A=Position on some entities and B=Velocity on others, seeded.
struct ViewFixture {
  Registry reg;
  std::vector<Entity> es;
  EntitySet with_both;

  ViewFixture(std::uint32_t seed, int n, double p_position, double p_velocity) {
    std::mt19937 rng(seed);
    std::bernoulli_distribution has_position(p_position);
    std::bernoulli_distribution has_velocity(p_velocity);
    for (int i = 0; i < n; ++i) {
      const Entity e = reg.create();
      es.push_back(e);
      const bool p = has_position(rng);
      const bool v = has_velocity(rng);
      if (p) reg.emplace<Position>(e, float(i));
      if (v) reg.emplace<Velocity>(e, float(i));
      if (i % 4 == 0) reg.emplace<Tag>(e);
      if (p && v) with_both.insert(e);
    }
  }
};

TEST(EcsView, VisitsExactlyTheEntitiesWithAllComponents) {
  // Both pool-size orders, so either pool may lead the walk.
  for (const auto& [p_position, p_velocity] : {std::pair(0.7, 0.3), std::pair(0.3, 0.7)}) {
    ViewFixture fx(99u, 400, p_position, p_velocity);
    EntitySet visited;
    fx.reg.view<Position, Velocity>().each([&](Entity e, Position& p, Velocity& v) {
      EXPECT_TRUE(visited.insert(e).second) << "visited twice";
      EXPECT_EQ(&p, &fx.reg.get<Position>(e)) << "each() passes the stored components";
      EXPECT_EQ(&v, &fx.reg.get<Velocity>(e));
    });
    EXPECT_EQ(visited, fx.with_both);
    EXPECT_EQ((fx.reg.view<Position, Velocity>().size()), fx.with_both.size());
    const std::vector<Entity> listed = fx.reg.view<Position, Velocity>().entities();
    EntitySet listed_set;
    listed_set.insert(listed.begin(), listed.end());
    EXPECT_EQ(listed.size(), listed_set.size());
    EXPECT_EQ(listed_set, fx.with_both);

    // The component-only signature, and writes through the references.
    fx.reg.view<Position, Velocity>().each([](Position& p, Velocity& v) { p.y = v.dx + 1.0f; });
    for (const Entity e : fx.with_both)
      EXPECT_EQ(fx.reg.get<Position>(e).y, fx.reg.get<Velocity>(e).dx + 1.0f);

    // Three components including an empty tag type.
    std::size_t tagged = 0;
    for (const Entity e : fx.with_both) tagged += fx.reg.has<Tag>(e) ? 1 : 0;
    std::size_t seen = 0;
    fx.reg.view<Tag, Position, Velocity>().each([&](Entity e, Tag&, Position&, Velocity&) {
      EXPECT_TRUE((fx.reg.has<Tag, Position, Velocity>(e)));
      ++seen;
    });
    EXPECT_EQ(seen, tagged);
  }
}

TEST(EcsView, EmptyAndMissingPoolsGiveEmptyViews) {
  Registry reg;
  int calls = 0;
  reg.view<Position>().each([&](Position&) { ++calls; });
  const Entity e = reg.create();
  reg.emplace<Position>(e);
  reg.view<Position, Velocity>().each([&](Position&, Velocity&) { ++calls; });
  EXPECT_EQ(calls, 0);
  EXPECT_EQ((reg.view<Position, Velocity>().size()), 0u);
}

TEST(EcsView, RemovingFromTheVisitedEntityVisitsEveryOtherOnce) {
  for (const auto& [p_position, p_velocity] : {std::pair(0.8, 0.4), std::pair(0.4, 0.8)}) {
    for (int which = 0; which < 3; ++which) { // remove Position, Velocity, or both
      ViewFixture fx(5u + std::uint32_t(which), 500, p_position, p_velocity);
      std::map<std::uint32_t, int> visits;
      fx.reg.view<Position, Velocity>().each([&](Entity e, Position&, Velocity&) {
        ++visits[e.index];
        if (which != 1) fx.reg.remove<Position>(e);
        if (which != 0) fx.reg.remove<Velocity>(e);
      });
      EXPECT_EQ(visits.size(), fx.with_both.size());
      for (const Entity e : fx.with_both) EXPECT_EQ(visits[e.index], 1);
      EXPECT_EQ((fx.reg.view<Position, Velocity>().size()), 0u);
    }
  }
}

TEST(EcsView, DestroyingTheVisitedEntityVisitsEveryOtherOnce) {
  for (const auto& [p_position, p_velocity] : {std::pair(0.8, 0.4), std::pair(0.4, 0.8)}) {
    ViewFixture fx(11u, 500, p_position, p_velocity);
    std::map<std::uint32_t, int> visits;
    fx.reg.view<Position, Velocity>().each([&](Entity e, Position&, Velocity&) {
      ++visits[e.index];
      fx.reg.destroy(e);
    });
    EXPECT_EQ(visits.size(), fx.with_both.size());
    for (const Entity e : fx.with_both) {
      EXPECT_EQ(visits[e.index], 1);
      EXPECT_FALSE(fx.reg.valid(e));
    }
    EXPECT_EQ(fx.reg.alive(), fx.es.size() - fx.with_both.size());
  }
}

TEST(EcsView, EntitiesJoiningDuringTheWalkAreNotVisited) {
  for (const auto& [p_position, p_velocity] : {std::pair(0.8, 0.4), std::pair(0.4, 0.8)}) {
    ViewFixture fx(23u, 500, p_position, p_velocity);
    EntitySet visited;
    EntitySet joined;
    fx.reg.view<Position, Velocity>().each([&](Entity e, Position&, Velocity&) {
      visited.insert(e);
      // Existing entities join through either pool (so they sit ahead in the lead pool too)...
      for (const Entity other : fx.es) {
        if (!fx.reg.valid(other) || fx.reg.has<Position, Velocity>(other)) continue;
        if (!fx.reg.has<Position>(other)) fx.reg.emplace<Position>(other);
        if (!fx.reg.has<Velocity>(other)) fx.reg.emplace<Velocity>(other);
        joined.insert(other);
        break;
      }
      // ...and new entities join with both.
      const Entity fresh = fx.reg.create();
      fx.reg.emplace<Velocity>(fresh);
      fx.reg.emplace<Position>(fresh);
      joined.insert(fresh);
    });
    EXPECT_EQ(visited, fx.with_both);
    for (const Entity e : joined) EXPECT_EQ(visited.count(e), 0u);
    EXPECT_EQ((fx.reg.view<Position, Velocity>().size()), fx.with_both.size() + joined.size())
        << "the joiners are in the view for the next walk";
  }
}

TEST(EcsView, EntitiesLeavingBeforeTheirTurnAreSkippedAndTheRestVisitedOnce) {
  ViewFixture fx(31u, 400, 0.6, 0.6);
  const std::vector<Entity> order = fx.reg.view<Position, Velocity>().entities();
  ASSERT_GT(order.size(), 20u);
  std::vector<Entity> visited;
  EntitySet left;
  EntitySet recycled;
  fx.reg.view<Position, Velocity>().each([&](Entity e, Position&, Velocity&) {
    visited.push_back(e);
    if (visited.size() != 1) return;
    // On the first visit, make every third entity ahead leave the view, in different ways.
    for (std::size_t i = 1; i < order.size(); i += 3) {
      const Entity other = order[i];
      left.insert(other);
      switch (i % 4) {
      case 0:
        fx.reg.remove<Position>(other);
        break;
      case 1:
        fx.reg.remove<Velocity>(other);
        break;
      case 2:
        fx.reg.destroy(other);
        break;
      default: { // destroyed, and its slot recycled into a new entity in the view
        fx.reg.destroy(other);
        const Entity reuse = fx.reg.create();
        EXPECT_EQ(reuse.index, other.index);
        fx.reg.emplace<Position>(reuse);
        fx.reg.emplace<Velocity>(reuse);
        recycled.insert(reuse);
      }
      }
    }
  });
  std::vector<Entity> expected;
  for (const Entity e : order)
    if (left.count(e) == 0) expected.push_back(e);
  EXPECT_EQ(visited, expected) << "in snapshot order, each remaining entity exactly once";
  for (const Entity e : recycled) EXPECT_EQ(std::count(visited.begin(), visited.end(), e), 0);
}

TEST(EcsView, EntityThatLeavesAndRejoinsBeforeItsTurnIsVisited) {
  Registry reg;
  std::vector<Entity> es;
  for (int i = 0; i < 10; ++i) {
    es.push_back(reg.create());
    reg.emplace<Position>(es.back(), float(i));
  }
  const std::vector<Entity> order = reg.view<Position>().entities();
  const Entity last = order.back();
  std::vector<Entity> visited;
  reg.view<Position>().each([&](Entity e, Position&) {
    visited.push_back(e);
    if (visited.size() == 1) { // last leaves and rejoins: it is in the view when its turn comes
      reg.remove<Position>(last);
      reg.emplace<Position>(last, -1.0f);
    }
  });
  EXPECT_EQ(visited, order);
}

TEST(EcsView, RandomMutationsDuringEachFollowTheSnapshotRule) {
  // Exact check of rule 3 under arbitrary mutation: the walk visits snapshot entities in order,
  // each at most once, and every snapshot entity it skips is out of the view at its turn.
  std::mt19937 rng(424242u);
  for (int trial = 0; trial < 20; ++trial) {
    ViewFixture fx(1000u + std::uint32_t(trial), 300, 0.6, 0.5);
    const std::vector<Entity> order = fx.reg.view<Position, Velocity>().entities();
    std::size_t next = 0; // position in `order` the walk should reach next
    auto check_skipped_until = [&](std::size_t end) {
      for (; next < end; ++next)
        EXPECT_FALSE((fx.reg.has<Position, Velocity>(order[next]))) << "skipped while in the view";
    };
    auto random_entity = [&] {
      return fx.es[std::uniform_int_distribution<std::size_t>(0, fx.es.size() - 1)(rng)];
    };
    fx.reg.view<Position, Velocity>().each([&](Entity e, Position&, Velocity&) {
      const auto it = std::find(order.begin() + std::ptrdiff_t(next), order.end(), e);
      ASSERT_NE(it, order.end()) << "visited an entity not in the snapshot, or out of order";
      check_skipped_until(std::size_t(it - order.begin()));
      ++next;
      for (int k = 0; k < 4; ++k) {
        const Entity target = random_entity();
        if (!fx.reg.valid(target)) continue;
        switch (std::uniform_int_distribution<int>(0, 5)(rng)) {
        case 0:
          fx.reg.remove<Position>(target);
          break;
        case 1:
          fx.reg.remove<Velocity>(target);
          break;
        case 2:
          fx.reg.emplace_or_replace<Position>(target);
          break;
        case 3:
          fx.reg.emplace_or_replace<Velocity>(target);
          break;
        case 4:
          fx.reg.destroy(target);
          break;
        default: {
          const Entity fresh = fx.reg.create();
          fx.es.push_back(fresh);
          fx.reg.emplace<Position>(fresh);
          fx.reg.emplace<Velocity>(fresh);
        }
        }
      }
    });
    check_skipped_until(order.size());
  }
}

// --- Rule 4: resources -----------------------------------------------------------------------

struct FrameCounter {
  int frames = 0;
};

TEST(EcsResources, AreOnePerTypePerRegistry) {
  Registry a;
  Registry b;
  EXPECT_EQ(a.try_resource<FrameCounter>(), nullptr);
  a.set_resource<FrameCounter>(FrameCounter{3});
  EXPECT_EQ(b.try_resource<FrameCounter>(), nullptr) << "a resource belongs to one registry";
  EXPECT_EQ(a.resource<FrameCounter>().frames, 3);

  b.resource_or_default<FrameCounter>().frames = 10;
  EXPECT_EQ(b.resource<FrameCounter>().frames, 10);
  EXPECT_EQ(a.resource<FrameCounter>().frames, 3);
  FrameCounter& same = b.resource_or_default<FrameCounter>();
  EXPECT_EQ(&same, b.try_resource<FrameCounter>())
      << "resource_or_default returns the existing one";
  EXPECT_EQ(same.frames, 10);

  a.set_resource<std::string>("library");
  const std::string* library = std::as_const(a).try_resource<std::string>();
  ASSERT_NE(library, nullptr);
  EXPECT_EQ(*library, "library");
  EXPECT_EQ(a.resource<FrameCounter>().frames, 3) << "types do not share slots";
  EXPECT_EQ(b.try_resource<std::string>(), nullptr);

  a.set_resource<FrameCounter>(FrameCounter{4}); // set replaces
  EXPECT_EQ(a.resource<FrameCounter>().frames, 4);
}

TEST(EcsResources, AreDestroyedByClearAndByTheRegistry) {
  int live = 0;
  {
    Registry reg;
    reg.set_resource<Counted>(&live, 1);
    EXPECT_EQ(live, 1);
    reg.set_resource<Counted>(&live, 2); // the replaced one is destroyed
    EXPECT_EQ(live, 1);
    EXPECT_EQ(reg.resource<Counted>().value(), 2);
    reg.clear();
    EXPECT_EQ(live, 0);
    EXPECT_EQ(reg.try_resource<Counted>(), nullptr);
    reg.set_resource<Counted>(&live, 3);
  }
  EXPECT_EQ(live, 0);
}

// --- Lifetimes: every constructed component is destroyed exactly once ------------------------

TEST(EcsLifetime, ComponentDestructorsRunOnRemoveDestroyClearAndRegistryDestruction) {
  int live = 0;
  {
    Registry reg;
    std::vector<Entity> es;
    for (int i = 0; i < 700; ++i) {
      es.push_back(reg.create());
      reg.emplace<Counted>(es.back(), &live, i);
    }
    EXPECT_EQ(live, 700);
    for (int i = 0; i < 700; i += 3) reg.remove<Counted>(es[std::size_t(i)]);
    EXPECT_EQ(std::size_t(live), reg.count<Counted>());
    for (int i = 1; i < 700; i += 3) reg.destroy(es[std::size_t(i)]);
    EXPECT_EQ(std::size_t(live), reg.count<Counted>());
    for (int i = 2; i < 700; i += 3) reg.emplace_or_replace<Counted>(es[std::size_t(i)], &live, -i);
    EXPECT_EQ(std::size_t(live), reg.count<Counted>());
    for (int i = 2; i < 700; i += 3) EXPECT_EQ(reg.get<Counted>(es[std::size_t(i)]).value(), -i);
    reg.clear();
    EXPECT_EQ(live, 0);

    for (int i = 0; i < 300; ++i) reg.emplace<Counted>(reg.create(), &live, i);
    EXPECT_EQ(live, 300);
  } // the registry's destructor destroys the rest
  EXPECT_EQ(live, 0);
}

TEST(EcsLifetime, ThrowingConstructorLeavesThePoolUnchanged) {
  Registry reg;
  const Entity a = reg.create();
  const Entity b = reg.create();
  reg.emplace<ThrowsOnConstruct>(a, false);
  EXPECT_THROW(reg.emplace<ThrowsOnConstruct>(b, true), std::runtime_error);
  EXPECT_FALSE(reg.has<ThrowsOnConstruct>(b));
  EXPECT_TRUE(reg.has<ThrowsOnConstruct>(a));
  EXPECT_EQ(reg.count<ThrowsOnConstruct>(), 1u);
  reg.emplace<ThrowsOnConstruct>(b, false); // the failed attempt left no trace
  EXPECT_EQ(reg.count<ThrowsOnConstruct>(), 2u);
}

TEST(EcsLifetime, MovedRegistryKeepsEntitiesAndTheMovedFromOneIsEmpty) {
  int live = 0;
  Registry source;
  const Entity e = source.create();
  source.emplace<Counted>(e, &live, 42);
  source.set_resource<FrameCounter>(FrameCounter{7});

  Registry target(std::move(source));
  EXPECT_TRUE(target.valid(e));
  EXPECT_EQ(target.get<Counted>(e).value(), 42);
  EXPECT_EQ(target.resource<FrameCounter>().frames, 7);
  EXPECT_EQ(source.alive(), 0u); // documented: moved-from is empty
  EXPECT_FALSE(source.valid(e));
  EXPECT_EQ(source.try_resource<FrameCounter>(), nullptr);

  Registry other;
  static_cast<void>(other.create());
  other.emplace<Counted>(other.create(), &live, 1);
  EXPECT_EQ(live, 2);
  other = std::move(target); // other's own component is destroyed
  EXPECT_EQ(live, 1);
  EXPECT_EQ(other.get<Counted>(e).value(), 42);
  EXPECT_EQ(other.alive(), 1u);
  EXPECT_EQ(target.alive(), 0u);
  other.clear();
  EXPECT_EQ(live, 0);
}

// --- Randomized property test against a reference model --------------------------------------

struct ModelEntity {
  std::optional<int> position; // Position.x as int
  std::optional<std::string> name;
  std::optional<int> counted;
};

TEST(EcsProperty, RandomOperationsMatchAReferenceModel) {
  std::mt19937 rng(0x5eed1234u);
  int live_counted = 0;
  {
    Registry reg;
    std::map<std::pair<std::uint32_t, std::uint32_t>, ModelEntity> model;
    std::vector<Entity> handles; // every handle ever created, stale ones included
    auto key = [](Entity e) { return std::pair(e.index, e.generation); };
    auto pick = [&]() -> Entity {
      if (handles.empty()) return null_entity;
      return handles[std::uniform_int_distribution<std::size_t>(0, handles.size() - 1)(rng)];
    };

    for (int step = 0; step < 4000; ++step) {
      const int op = std::uniform_int_distribution<int>(0, 9)(rng);
      const int value = std::uniform_int_distribution<int>(-1000, 1000)(rng);
      const Entity e = pick();
      const bool live = model.count(key(e)) != 0;
      switch (op) {
      case 0:
      case 1: {
        const Entity fresh = reg.create();
        ASSERT_EQ(model.count(key(fresh)), 0u) << "create() returned a handle in use";
        ASSERT_EQ(std::count(handles.begin(), handles.end(), fresh), 0) << "handle reused";
        model[key(fresh)];
        handles.push_back(fresh);
        break;
      }
      case 2:
        reg.destroy(e);
        model.erase(key(e));
        break;
      case 3:
        if (live && !model[key(e)].position) {
          reg.emplace<Position>(e, float(value));
          model[key(e)].position = value;
        }
        break;
      case 4:
        if (live) {
          reg.emplace_or_replace<std::string>(e, std::to_string(value));
          model[key(e)].name = std::to_string(value);
        }
        break;
      case 5:
        if (live) {
          reg.emplace_or_replace<Counted>(e, &live_counted, value);
          model[key(e)].counted = value;
        }
        break;
      case 6:
        ASSERT_EQ(reg.remove<Position>(e), live && model[key(e)].position.has_value());
        if (live) model[key(e)].position.reset();
        break;
      case 7:
        ASSERT_EQ(reg.remove<std::string>(e), live && model[key(e)].name.has_value());
        if (live) model[key(e)].name.reset();
        break;
      case 8:
        ASSERT_EQ(reg.remove<Counted>(e), live && model[key(e)].counted.has_value());
        if (live) model[key(e)].counted.reset();
        break;
      default:
        if (live && model[key(e)].position) { // write through get()
          reg.get<Position>(e).x += 1.0f;
          *model[key(e)].position += 1;
        }
        break;
      }

      // Compare everything after every step.
      ASSERT_EQ(reg.alive(), model.size()) << "step " << step;
      std::size_t positions = 0, names = 0, counteds = 0, both = 0;
      for (const Entity h : handles) {
        const auto it = model.find(key(h));
        ASSERT_EQ(reg.valid(h), it != model.end()) << "step " << step;
        if (it == model.end()) {
          ASSERT_FALSE(reg.has<Position>(h));
          ASSERT_EQ(reg.try_get<std::string>(h), nullptr);
          continue;
        }
        const ModelEntity& m = it->second;
        ASSERT_EQ(reg.has<Position>(h), m.position.has_value()) << "step " << step;
        ASSERT_EQ(reg.has<std::string>(h), m.name.has_value()) << "step " << step;
        ASSERT_EQ(reg.has<Counted>(h), m.counted.has_value()) << "step " << step;
        if (m.position) {
          ASSERT_EQ(reg.get<Position>(h).x, float(*m.position)) << "step " << step;
        }
        if (m.name) {
          ASSERT_EQ(reg.get<std::string>(h), *m.name) << "step " << step;
        }
        if (m.counted) {
          ASSERT_EQ(reg.get<Counted>(h).value(), *m.counted) << "step " << step;
        }
        positions += m.position ? 1 : 0;
        names += m.name ? 1 : 0;
        counteds += m.counted ? 1 : 0;
        both += m.position && m.name ? 1 : 0;
      }
      ASSERT_EQ(reg.count<Position>(), positions);
      ASSERT_EQ(reg.count<std::string>(), names);
      ASSERT_EQ(reg.count<Counted>(), counteds);
      ASSERT_EQ(std::size_t(live_counted), counteds) << "leaked or double-destroyed component";
      ASSERT_EQ((reg.view<Position, std::string>().size()), both);
      std::size_t walked = 0;
      reg.each_entity([&](Entity h) {
        ASSERT_EQ(model.count(key(h)), 1u);
        ++walked;
      });
      ASSERT_EQ(walked, model.size());
    }
  }
  EXPECT_EQ(live_counted, 0);
}

// --- Rule 5: change versions ---

struct Health {
  int value = 0;
};
struct Speed {
  float value = 0.0f;
};

TEST(EcsVersions, GrowOnMembershipChangesOfTheirTypeOnly) {
  Registry reg;
  EXPECT_EQ(reg.version<Health>(), 0u);
  const Entity a = reg.create();
  const Entity b = reg.create();
  reg.emplace<Health>(a);
  const std::uint64_t after_add = reg.version<Health>();
  EXPECT_GT(after_add, 0u);
  reg.emplace<Speed>(b); // another type: Health's version stays
  EXPECT_EQ(reg.version<Health>(), after_add);
  reg.emplace<Health>(b);
  const std::uint64_t two = reg.version<Health>();
  EXPECT_GT(two, after_add);
  reg.remove<Health>(a);
  const std::uint64_t removed = reg.version<Health>();
  EXPECT_GT(removed, two);
  EXPECT_FALSE(reg.remove<Health>(a)); // nothing to remove: no change
  EXPECT_EQ(reg.version<Health>(), removed);
  reg.destroy(b); // destroying an entity removes its Health (and its Speed)
  EXPECT_GT(reg.version<Health>(), removed);
  reg.emplace<Speed>(a);
  const std::uint64_t before_clear = reg.version<Speed>();
  reg.clear();
  EXPECT_GT(reg.version<Speed>(), before_clear);
  const std::uint64_t after_clear = reg.version<Speed>();
  reg.clear(); // nothing left to clear: no change
  EXPECT_EQ(reg.version<Speed>(), after_clear);
}

TEST(EcsVersions, PatchAndReplaceAreRecordedPlainEditsAreNot) {
  Registry reg;
  const Entity e = reg.create();
  reg.emplace<Health>(e, Health{3});
  const std::uint64_t v0 = reg.version<Health>();
  reg.get<Health>(e).value = 4; // a plain edit: invisible by contract
  EXPECT_EQ(reg.version<Health>(), v0);
  const Health& h = reg.patch<Health>(e, [](Health& x) { x.value = 5; });
  EXPECT_EQ(h.value, 5);
  EXPECT_EQ(reg.get<Health>(e).value, 5);
  const std::uint64_t v1 = reg.version<Health>();
  EXPECT_GT(v1, v0);
  reg.emplace_or_replace<Health>(e, Health{6});
  EXPECT_GT(reg.version<Health>(), v1);
  EXPECT_EQ(reg.get<Health>(e).value, 6);
}

} // namespace

// The journal survives kill -9 at any moment: every reopened journal is consistent, no stored scan is lost,
// none is repeated, no partial file is referenced, and the job resumes at its first unfinished view.
#include <chrono>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <random>
#include <thread>

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include "daemon/journal.hpp"

namespace dm = scancell::daemon;
namespace fs = std::filesystem;

namespace {

/// A scan's bytes, reproducible from its view index (200 KB: the write and fsync take long enough for kills
/// to land inside them).
std::string payload(int view) {
  std::string s(200 * 1024, '\0');
  std::mt19937 rng(static_cast<unsigned>(view) * 7919u + 1u);
  for (auto& c : s) c = static_cast<char>(rng() & 0xFF);
  return s;
}

fs::path fresh_dir(const std::string& name) {
  const fs::path d = fs::temp_directory_path() / ("scancell-journal-" + name + "-" + std::to_string(::getpid()));
  fs::remove_all(d);
  return d;
}

}  // namespace

TEST(Journal, StatesPlansScansAndEvents) {
  const fs::path dir = fresh_dir("basic");
  {
    dm::Journal j(dir);
    const auto job = j.create_job("mushroom.off", "{\"spec\":\"thesis\"}");
    j.set_state(job, dm::JobState::planning);
    const auto plan = j.add_plan(job, 0, {"{\"k\":0}", "{\"k\":1}"});
    j.set_state(job, dm::JobState::executing);
    EXPECT_EQ(j.first_unfinished_view(plan)->index, 0);
    const auto rec = j.store_scan(plan, 0, payload(0));
    EXPECT_EQ(j.read_scan(rec), payload(0));
    EXPECT_THROW(j.store_scan(plan, 0, payload(0)), dm::JournalError);  // never twice
    EXPECT_EQ(j.first_unfinished_view(plan)->index, 1);
    EXPECT_EQ(j.unfinished_jobs().size(), 1u);
    j.set_state(job, dm::JobState::faulted, "lift: register 1 (status): timeout");
    EXPECT_EQ(j.job(job).cause, "lift: register 1 (status): timeout");
    const auto ev = j.events(job);
    ASSERT_EQ(ev.size(), 5u);
    EXPECT_EQ(ev.back(), "faulted: lift: register 1 (status): timeout");
    // The job state machine (journal.cpp): a faulted job goes on only through resume (queued); a finished
    // one never moves again; each refusal names both states.
    try {
      j.set_state(job, dm::JobState::done);
      ADD_FAILURE() << "faulted -> done accepted";
    } catch (const dm::JournalError& e) {
      EXPECT_NE(std::string(e.what()).find("cannot go from faulted to done"), std::string::npos) << e.what();
    }
    EXPECT_EQ(j.job(job).state, dm::JobState::faulted);  // unchanged, and no event written
    EXPECT_EQ(j.events(job).size(), 5u);
    j.set_state(job, dm::JobState::queued, "resumed");
    j.set_state(job, dm::JobState::executing);
    j.set_state(job, dm::JobState::done);
    EXPECT_TRUE(j.unfinished_jobs().empty());
    EXPECT_THROW(j.set_state(job, dm::JobState::executing), dm::JournalError);
    EXPECT_THROW(j.set_state(job, dm::JobState::queued), dm::JournalError);
    EXPECT_FALSE(dm::transition_allowed(dm::JobState::paused, dm::JobState::executing));  // resume queues first
    EXPECT_TRUE(dm::transition_allowed(dm::JobState::executing, dm::JobState::verifying));
    EXPECT_TRUE(dm::transition_allowed(dm::JobState::verifying, dm::JobState::executing));  // the next round
  }
  {
    // A damaged file is found by check().
    dm::Journal j(dir);
    std::ofstream(dir / "scans" / "p1-v0.bin", std::ios::binary | std::ios::trunc) << "short";
    const auto problems = j.check();
    ASSERT_EQ(problems.size(), 1u);
    EXPECT_NE(problems[0].find("bytes, journal says"), std::string::npos) << problems[0];
  }
  fs::remove_all(dir);
}

TEST(Journal, SurvivesKillNineAtAnyMoment) {
  // 24 kills at random moments while a child stores scans; each time the journal is reopened and checked.
  // When a plan round completes, the next round starts (as a replan would), so every kill lands in work.
  const fs::path dir = fresh_dir("kill");
  constexpr int kViews = 40;
  std::int64_t job = 0;
  std::vector<std::string> poses;
  for (int k = 0; k < kViews; ++k) poses.push_back("{\"view\":" + std::to_string(k) + "}");
  std::vector<std::int64_t> plans;
  {
    dm::Journal j(dir);
    job = j.create_job("object.off", "{}");
    plans.push_back(j.add_plan(job, 0, poses));
    j.set_state(job, dm::JobState::executing);
  }
  auto run_child = [&](std::int64_t plan) {
    const pid_t pid = ::fork();
    if (pid == 0) {
      try {
        dm::Journal j(dir);
        while (auto v = j.first_unfinished_view(plan)) j.store_scan(plan, v->index, payload(v->index));
      } catch (...) {
        ::_exit(2);
      }
      ::_exit(0);
    }
    return pid;
  };
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> delay_us(0, 6000);
  std::size_t stored_before = 0;
  for (int iteration = 0; iteration < 24; ++iteration) {
    const pid_t pid = run_child(plans.back());
    std::this_thread::sleep_for(std::chrono::microseconds(delay_us(rng)));
    ::kill(pid, SIGKILL);
    int status = 0;
    ::waitpid(pid, &status, 0);
    dm::Journal j(dir);  // reopening also clears a temp file the kill left behind
    const auto problems = j.check();
    EXPECT_TRUE(problems.empty()) << problems.front();
    std::size_t stored = 0;
    for (auto plan : plans) {
      const auto scans = j.scans(plan);
      stored += scans.size();
      for (std::size_t k = 0; k < scans.size(); ++k) {
        ASSERT_EQ(scans[k].view, static_cast<int>(k)) << "views are stored in order, none skipped or repeated";
        ASSERT_EQ(j.read_scan(scans[k]), payload(scans[k].view));
      }
    }
    EXPECT_GE(stored, stored_before) << "a stored scan was lost";
    stored_before = stored;
    for (const auto& e : fs::directory_iterator(dir / "scans")) EXPECT_NE(e.path().extension(), ".tmp");
    if (!j.first_unfinished_view(plans.back())) plans.push_back(j.add_plan(job, static_cast<int>(plans.size()), poses));
  }
  // Finish the last round without a kill: exactly one scan per view, all intact.
  const pid_t pid = run_child(plans.back());
  int status = 0;
  ::waitpid(pid, &status, 0);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  dm::Journal j(dir);
  EXPECT_TRUE(j.check().empty());
  ASSERT_EQ(j.scans(plans.back()).size(), static_cast<std::size_t>(kViews));
  EXPECT_FALSE(j.first_unfinished_view(plans.back()).has_value());
  fs::remove_all(dir);
}

// `scancelld --check` opens the journal beside a running daemon: a temp file there may be the scan the daemon
// is writing, and removing it faulted the job at its rename (daemon_cli, 2026-11-29). Only the owner clears
// what a crash left behind.
TEST(Journal, InspectingLeavesAScanBeingWrittenAlone) {
  const fs::path dir = fresh_dir("inspect");
  { dm::Journal own(dir); }
  const fs::path tmp = dir / "scans" / "p1-v2.bin.tmp";
  std::ofstream(tmp) << "half a scan";
  { dm::Journal inspect(dir, dm::Journal::Open::inspect); }
  EXPECT_TRUE(fs::exists(tmp));
  { dm::Journal own(dir); }
  EXPECT_FALSE(fs::exists(tmp));
  fs::remove_all(dir);
}

// The process launcher (core/process.h) on /bin/sh: exit codes and signals, output files
// (truncated or appended), working directory, default environment, a program that cannot start,
// and several children waited for in whatever order they end.
#include "core/process.h"

#include <gtest/gtest.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <stdexcept>

#include "core/atomic_file.h"
#include "tests/temp_dir.h"

namespace raytime {
namespace {

// A command line the shell reads back word for word, whatever the words hold (scripts are
// generated from it: the Slurm backend's task script).
TEST(Process, CommandLineWordsSurviveTheShell) {
  TempDir dir("process");
  const std::vector<std::string> words = {
      "plain-word_1.yaml", "a b", "it's", "$HOME", "x;y", "*", "a|b&c", "(x)", "~", "", "k=v,w"};
  ProcessOptions options;
  options.output_path = dir / "words.txt";
  options.append_output = false;
  ASSERT_TRUE(
      RunProcess({"/bin/sh", "-c", "printf '<%s>\\n' " + CommandLine(words)}, options).Succeeded());
  std::string expected;
  for (const std::string& word : words) expected += "<" + word + ">\n";
  EXPECT_EQ(ReadTextFile(options.output_path), expected);
  EXPECT_EQ(CommandLine({"raytime", "run", "a.yaml"}), "raytime run a.yaml");
}

TEST(Process, ExitCodeAndOutputFile) {
  TempDir dir("process");
  ProcessOptions options;
  options.output_path = dir / "out.log";
  options.append_output = false;
  const ProcessStatus status =
      RunProcess({"/bin/sh", "-c", "echo hi; echo err >&2; exit 3"}, options);
  EXPECT_EQ(status.exit_code, 3);
  EXPECT_EQ(status.signal, 0);
  EXPECT_FALSE(status.Succeeded());
  EXPECT_EQ(status.Describe(), "exited with status 3");
  EXPECT_EQ(ReadTextFile(options.output_path), "hi\nerr\n");

  options.append_output = true;
  EXPECT_TRUE(RunProcess({"/bin/sh", "-c", "echo again"}, options).Succeeded());
  EXPECT_EQ(ReadTextFile(options.output_path), "hi\nerr\nagain\n");
  options.append_output = false;
  EXPECT_TRUE(RunProcess({"/bin/sh", "-c", "echo fresh"}, options).Succeeded());
  EXPECT_EQ(ReadTextFile(options.output_path), "fresh\n");
}

TEST(Process, LooksUpThePathAndReadsNothingFromStdin) {
  TempDir dir("process");
  ProcessOptions options;
  options.output_path = dir / "out.log";
  EXPECT_TRUE(RunProcess({"sh", "-c", "readlink /proc/self/fd/0"}, options).Succeeded());
  EXPECT_EQ(ReadTextFile(options.output_path), "/dev/null\n");
}

TEST(Process, WorkingDirectoryAndDefaultEnvironment) {
  TempDir dir("process");
  std::filesystem::create_directories(dir / "sub");
  ProcessOptions options;
  options.output_path = dir / "out.log";  // the caller's path, opened before the chdir
  options.working_dir = dir / "sub";
  options.default_environment = {"RAYTIME_PROCESS_TEST=default"};
  ::unsetenv("RAYTIME_PROCESS_TEST");
  EXPECT_TRUE(RunProcess({"sh", "-c", "pwd; echo $RAYTIME_PROCESS_TEST"}, options).Succeeded());
  const std::string sub = std::filesystem::canonical(dir / "sub").string();
  EXPECT_EQ(ReadTextFile(options.output_path), sub + "\ndefault\n");

  // The caller's environment wins over a default.
  ::setenv("RAYTIME_PROCESS_TEST", "caller", 1);
  options.append_output = false;
  EXPECT_TRUE(RunProcess({"sh", "-c", "echo $RAYTIME_PROCESS_TEST"}, options).Succeeded());
  ::unsetenv("RAYTIME_PROCESS_TEST");
  EXPECT_EQ(ReadTextFile(options.output_path), "caller\n");
}

TEST(Process, AProgramThatCannotStartNamesIt) {
  try {
    StartProcess({"raytime-no-such-program", "--flag"});
    FAIL() << "expected an error";
  } catch (const std::runtime_error& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find("cannot run 'raytime-no-such-program --flag'"), std::string::npos)
        << message;
    EXPECT_NE(message.find("No such file"), std::string::npos) << message;
  }
  TempDir dir("process");
  ProcessOptions options;
  options.working_dir = dir / "missing";
  EXPECT_THROW(StartProcess({"/bin/sh", "-c", "exit 0"}, options), std::runtime_error);
}

TEST(Process, WaitsForSeveralChildrenAndSignalsOne) {
  std::map<pid_t, int> expected;
  for (int code : {4, 5, 6}) {
    expected[StartProcess({"/bin/sh", "-c", "exit " + std::to_string(code)})] = code;
  }
  const pid_t sleeper = StartProcess({"sleep", "60"});
  for (int n = 0; n < 3; ++n) {
    const FinishedProcess finished = WaitAnyProcess();
    ASSERT_EQ(expected.count(finished.pid), 1u) << finished.pid;
    EXPECT_EQ(finished.status.exit_code, expected[finished.pid]);
    expected.erase(finished.pid);
  }
  EXPECT_TRUE(SignalProcess(sleeper, SIGTERM));
  const FinishedProcess finished = WaitAnyProcess();
  EXPECT_EQ(finished.pid, sleeper);
  EXPECT_EQ(finished.status.signal, SIGTERM);
  EXPECT_EQ(finished.status.exit_code, -1);
  EXPECT_EQ(finished.status.Describe(), "was killed by signal " + std::to_string(SIGTERM));
  EXPECT_THROW(WaitAnyProcess(), std::runtime_error) << "no children are left";
}

// A child in its own process group: waiting with a limit returns while it runs, and signalling the
// group ends what the child started too (the trainer hook's timeout and interruption rely on it).
TEST(Process, WaitsWithALimitAndSignalsAWholeGroup) {
  TempDir dir("process");
  ProcessOptions options;
  options.new_process_group = true;
  const std::string grandchild_pid = dir / "grandchild.pid";
  const pid_t shell =
      StartProcess({"/bin/sh", "-c", "sleep 60 & echo $! > " + grandchild_pid + "; wait"}, options);
  EXPECT_EQ(::getpgid(shell), shell) << "the child leads its own group";
  ProcessStatus status;
  EXPECT_FALSE(WaitProcessFor(shell, 0.2, &status));
  ASSERT_TRUE(std::filesystem::exists(grandchild_pid));
  const pid_t grandchild = std::stoi(ReadTextFile(grandchild_pid));
  EXPECT_EQ(::getpgid(grandchild), shell);

  EXPECT_TRUE(SignalProcessGroup(shell, SIGTERM));
  ASSERT_TRUE(WaitProcessFor(shell, 10.0, &status));
  EXPECT_EQ(status.signal, SIGTERM);
  // The grandchild is not ours to reap: it counts as ended once it is gone or a zombie (whether
  // the container's init reaps orphans is not this test's business).
  const auto running = [&] {
    std::ifstream stat("/proc/" + std::to_string(grandchild) + "/stat");
    std::string pid, name, state;
    return stat >> pid >> name >> state && state != "Z";
  };
  for (int i = 0; i < 200 && running(); ++i) ::usleep(10000);
  EXPECT_FALSE(running()) << "the sleep the shell started outlived the group's signal";

  const pid_t quick = StartProcess({"/bin/sh", "-c", "exit 7"});
  ASSERT_TRUE(WaitProcessFor(quick, 10.0, &status));
  EXPECT_EQ(status.exit_code, 7);
}

}  // namespace
}  // namespace raytime

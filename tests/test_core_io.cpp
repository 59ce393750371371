// File helpers (core/io.h): atomic output leaves no partial file, CSV reading names the
// file, line and column of every problem, output paths are refused before any work.
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>

#include "core/error.h"
#include "core/interrupt.h"
#include "core/io.h"
#include "tests/test_util.h"

namespace mcms {
namespace {

namespace fs = std::filesystem;

size_t FilesIn(const fs::path& dir) {
  size_t n = 0;
  for ([[maybe_unused]] const auto& e : fs::directory_iterator(dir)) ++n;
  return n;
}

TEST(Io, WriteFileAtomicallyWritesAndCreatesTheFolder) {
  const fs::path dir = test::ScratchDir("core_io_write");
  const fs::path p = dir / "sub" / "out.txt";
  WriteFileAtomically(p, [](std::ostream& o) { o << "a,b\n1,2\n"; });
  EXPECT_EQ(ReadTextFile(p), "a,b\n1,2\n");
  EXPECT_EQ(FilesIn(dir / "sub"), 1u) << "no temporary file left beside the output";
}

TEST(Io, AFailedWriteLeavesThePreviousFileAndNoPartialOne) {
  const fs::path dir = test::ScratchDir("core_io_fail");
  const fs::path p = dir / "out.txt";
  test::WriteText(p, "old\n");
  EXPECT_THROW(WriteFileAtomically(p,
                                   [](std::ostream& o) {
                                     o << "half of the new content";
                                     throw std::runtime_error("writer failed");
                                   }),
               std::runtime_error);
  EXPECT_EQ(ReadTextFile(p), "old\n");
  EXPECT_EQ(FilesIn(dir), 1u);
  // A fresh path stays absent.
  EXPECT_THROW(WriteFileAtomically(dir / "new.txt", [](std::ostream&) { throw std::runtime_error("x"); }),
               std::runtime_error);
  EXPECT_FALSE(fs::exists(dir / "new.txt"));
}

TEST(Io, ReadTextFileNamesAMissingFile) {
  const fs::path p = test::ScratchDir("core_io_missing") / "absent.csv";
  const std::string msg = test::ErrorOf([&] { ReadTextFile(p); });
  EXPECT_NE(msg.find(p.string()), std::string::npos) << msg;
}

TEST(Io, ReadCsvSkipsCommentsAndBlankLinesTrimsCellsAndKeepsLineNumbers) {
  const fs::path p = test::ScratchDir("core_io_csv") / "t.csv";
  test::WriteText(p, "# a comment\n time_s , x_m,name,note\r\n\n0.5, 1e-3 ,a,\n   \n2,-4.25,b b,last\n");
  const CsvTable t = ReadCsv(p);
  ASSERT_EQ(t.header, (std::vector<std::string>{"time_s", "x_m", "name", "note"}));
  ASSERT_EQ(t.rows.size(), 2u);
  EXPECT_EQ(t.line_of_row, (std::vector<int>{4, 6}));
  EXPECT_EQ(t.Column("x_m"), 1);
  EXPECT_TRUE(t.HasColumn("note"));
  EXPECT_FALSE(t.HasColumn("y_m"));
  EXPECT_EQ(t.Number(0, 0), 0.5);
  EXPECT_EQ(t.Number(0, 1), 1e-3);
  EXPECT_EQ(t.Number(1, 1), -4.25);
  EXPECT_EQ(t.rows[0][3], "") << "a trailing comma is an empty last cell";
  EXPECT_EQ(t.rows[1][2], "b b");
}

// Quoted cells as CsvQuoted writes them (a tracker's degraded reason holding a comma was
// refused by `mcms fuse` as a row with one column too many).
TEST(Io, ReadCsvReadsQuotedCellsAsCsvQuotedWritesThem) {
  const fs::path p = test::ScratchDir("core_io_csv_quoted") / "t.csv";
  const std::string reason = "only 2 balls seen, \"cam1\" blind";
  test::WriteText(p, "frame,reason,x_m\n1," + CsvQuoted(reason) + ",0.5\n2, \"a,b\" ,3\n3,,\n");
  const CsvTable t = ReadCsv(p);
  ASSERT_EQ(t.rows.size(), 3u);
  EXPECT_EQ(t.rows[0][1], reason);
  EXPECT_EQ(t.Number(0, 2), 0.5);
  EXPECT_EQ(t.rows[1][1], "a,b");
  EXPECT_EQ(t.Number(1, 2), 3);
  EXPECT_EQ(t.rows[2], (std::vector<std::string>{"3", "", ""}));
}

TEST(Io, ReadCsvErrorsNameFileLineAndColumn) {
  const fs::path dir = test::ScratchDir("core_io_csv_errors");
  test::WriteText(dir / "short.csv", "a,b,c\n1,2,3\n4,5\n");
  std::string msg = test::ErrorOf([&] { ReadCsv(dir / "short.csv"); });
  EXPECT_NE(msg.find("short.csv line 3"), std::string::npos) << msg;
  EXPECT_NE(msg.find("expected 3 columns"), std::string::npos) << msg;

  test::WriteText(dir / "empty.csv", "# only a comment\n\n");
  msg = test::ErrorOf([&] { ReadCsv(dir / "empty.csv"); });
  EXPECT_NE(msg.find("empty.csv"), std::string::npos) << msg;

  test::WriteText(dir / "cells.csv", "a,b\n1,x\n2,nan\n3,\n4,5abc\n");
  const CsvTable t = ReadCsv(dir / "cells.csv");
  msg = test::ErrorOf([&] { t.Column("z"); });
  EXPECT_NE(msg.find("'z'"), std::string::npos) << msg;
  for (size_t row = 0; row < t.rows.size(); ++row) {
    msg = test::ErrorOf([&] { t.Number(row, 1); });
    EXPECT_NE(msg.find("line " + std::to_string(row + 2)), std::string::npos) << msg;
    EXPECT_NE(msg.find("column 'b'"), std::string::npos) << msg;
  }
  EXPECT_EQ(t.Number(3, 0), 4.0);
}

TEST(Io, OutputPathsAreCheckedBeforeWork) {
  const fs::path dir = test::ScratchDir("core_io_paths");
  test::WriteText(dir / "file.txt", "x");
  fs::create_directories(dir / "folder");
  // A folder where a file is wanted, and the reverse, are refused with the option named.
  std::string msg = test::ErrorOf([&] { RequireWritableFile(dir / "folder", "-o"); });
  EXPECT_NE(msg.find("-o"), std::string::npos) << msg;
  EXPECT_NE(msg.find("is a folder"), std::string::npos) << msg;
  msg = test::ErrorOf([&] { RequireWritableFolder(dir / "file.txt", "--out"); });
  EXPECT_NE(msg.find("--out"), std::string::npos) << msg;
  // A path under an existing file cannot be created.
  msg = test::ErrorOf([&] { RequireWritableFile(dir / "file.txt" / "x.csv", "-o"); });
  EXPECT_NE(msg.find("not a folder"), std::string::npos) << msg;
  EXPECT_THROW(RequireWritableFile("", "-o"), InputError);
  EXPECT_THROW(RequireWritableFolder("", "-o"), InputError);
  // Writable places pass, whether they exist yet or not.
  EXPECT_NO_THROW(RequireWritableFile(dir / "file.txt", "-o"));
  EXPECT_NO_THROW(RequireWritableFile(dir / "new" / "deeper" / "x.csv", "-o"));
  EXPECT_NO_THROW(RequireWritableFolder(dir / "folder", "-o"));
  EXPECT_NO_THROW(RequireWritableFolder(dir / "new_folder", "-o"));
  EXPECT_FALSE(fs::exists(dir / "new")) << "checking creates nothing";
}

// A run ended by a signal leaves none of its registered temporaries (core/interrupt.h): a
// child process registers a folder tree and a file, is interrupted, and ends as the signal
// would have; what it did not register stays.
TEST(Io, AnInterruptedRunLeavesNoTemporaries) {
  const fs::path dir = test::ScratchDir("core_io_interrupt");
  for (int sig : {SIGINT, SIGTERM, SIGQUIT}) {
    fs::remove_all(dir);
    fs::create_directories(dir);
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      ::signal(SIGINT, SIG_DFL);  // (a background process may ignore it: set it as a terminal does)
      const struct rlimit no_core = {0, 0};
      ::setrlimit(RLIMIT_CORE, &no_core);  // (SIGQUIT's default action would dump core)
      InstallInterruptCleanup();
      fs::create_directories(dir / ".out.partial-1" / "images" / "cam0");
      for (int k = 0; k < 300; ++k) std::ofstream(dir / ".out.partial-1" / "images" / "cam0" / (std::to_string(k) + ".png")) << k;
      std::ofstream(dir / "poses.csv.rows.partial-1") << "rows";
      std::ofstream(dir / "mine.txt") << "the user's";
      RemovedOnInterrupt folder(dir / ".out.partial-1");
      RemovedOnInterrupt file(dir / "poses.csv.rows.partial-1");
      { RemovedOnInterrupt gone(dir / "mine.txt"); }  // unregistered again: stays
      ::raise(sig);
      ::_exit(0);
    }
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == sig) << "status " << status;
    EXPECT_FALSE(fs::exists(dir / ".out.partial-1"));
    EXPECT_FALSE(fs::exists(dir / "poses.csv.rows.partial-1"));
    EXPECT_TRUE(fs::exists(dir / "mine.txt"));
  }
}

}  // namespace
}  // namespace mcms

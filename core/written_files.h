// What raytime wrote into a folder (issue 47: nothing of the user's is lost). A folder raytime
// writes whole (an export's refined/, a 3dgs/<pose set>/ folder, a video's frames) holds a record,
// FOLDER/.raytime_written, of every file it wrote there: its path in the folder, size,
// modification time and (up to 64 MB) content checksum. Replacing or moving the folder touches
// those files only; anything else in it (a user's notes, a trainer's state kept beside the export,
// a file raytime wrote and someone has since changed) stays where it is, and a file of the user's
// under a name raytime is about to write stops the write, naming it, before anything is replaced.
#pragma once

#include <string>
#include <vector>

namespace raytime {

// The record's file name in each folder raytime writes whole.
inline constexpr char kWrittenFilesRecord[] = ".raytime_written";

// Records every file below `folder` (the record itself aside) as written by raytime.
void RecordWrittenFiles(const std::string& folder);

// Adds `relative` (a file raytime has just written below `folder`, after the folder itself) to the
// folder's record.
void RecordWrittenFile(const std::string& folder, const std::string& relative);

// The entries below `folder` that raytime did not write there, as paths relative to it: files and
// links the record does not list or whose size, or time and contents, changed since it did, and
// folders holding no file it wrote (one entry each, not their contents). A folder without a
// record (an earlier raytime's, or one a user made) is all theirs. Sorted.
std::vector<std::string> FilesNotWritten(const std::string& folder);

// The `entries` of folder `from` (FilesNotWritten) that collide with what folder `to` holds: the
// same path, or a path through one of its files, where not both are folders (two folders merge).
std::vector<std::string> CollidingEntries(const std::vector<std::string>& entries,
                                          const std::string& from, const std::string& to);

// Moves the `entries` of folder `from` into folder `to` at the same relative paths, merging
// folders; throws naming the first that cannot be moved (those before it are moved).
void CarryEntriesOver(const std::vector<std::string>& entries, const std::string& from,
                      const std::string& to);

// `wanted` when nothing is there, else the first of `wanted`.1, `wanted`.2, ... that is free: where
// something raytime keeps (an earlier folder, a stale copy) goes without replacing what is there.
std::string UnusedPath(const std::string& wanted);
// UnusedPath of `path`.<seconds since the epoch>: where an earlier move's result is kept when a
// new one needs its place (a stale/ slot holding the user's files, a trainer's derived files).
std::string DatedUnusedPath(const std::string& path);

}  // namespace raytime

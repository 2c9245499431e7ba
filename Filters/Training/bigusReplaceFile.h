/**
 * @file bigusReplaceFile.h
 * @brief Writing a file's replacement under a temporary name and renaming it over the file: a write that fails
 *        (a missing folder, a full disk) leaves what the user had untouched. Used by the checkpoints, the sequence
 *        writer and every output of the command line.
 *
 * Part of BIGUS::Training (public, not wrapped for Python).
 */
#ifndef bigusReplaceFile_h
#define bigusReplaceFile_h

#include "bigusTrainingModule.h" // For export macro

#include <string>

namespace bigus
{

/// "name.tmp<pid>.ext" for @p path "name.ext" (the first dot of the file name): the same folder and extension, so
/// that writers that choose the format by the extension write the same format.
BIGUSTRAINING_EXPORT std::string TemporaryName(const std::string& path);

/// Renames @p temporary over @p path (std::rename: POSIX replaces an existing @p path in one step; the
/// vtksys::SystemTools::RenameFile of later VTK releases is not in VTK 9.1). On failure the temporary is removed, @p
/// path is untouched, and the result is false.
BIGUSTRAINING_EXPORT bool Publish(const std::string& temporary, const std::string& path);

} // namespace bigus

#endif

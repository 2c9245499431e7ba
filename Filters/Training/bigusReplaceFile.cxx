#include "bigusReplaceFile.h"

#include <cstdio>
#include <unistd.h>

namespace bigus
{

std::string TemporaryName(const std::string& path)
{
  const std::size_t slash = path.find_last_of('/');
  const std::size_t dot = path.find('.', slash == std::string::npos ? 0 : slash + 1);
  const std::string tag = ".tmp" + std::to_string(::getpid());
  return dot == std::string::npos ? path + tag : path.substr(0, dot) + tag + path.substr(dot);
}

bool Publish(const std::string& temporary, const std::string& path)
{
  if (std::rename(temporary.c_str(), path.c_str()) != 0)
  {
    std::remove(temporary.c_str());
    return false;
  }
  return true;
}

} // namespace bigus

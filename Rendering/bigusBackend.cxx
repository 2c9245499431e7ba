// The backend registry (see bigusBackend.h).
#include "bigusBackend.h"
#include "bigusBackendCheck.h"

#include <algorithm>
#include <map>
#include <mutex>

#if defined(BIGUS_CUDA_BACKEND_LIBRARY)
#include <dlfcn.h>
#endif

namespace bigus
{

namespace
{
struct Entry
{
  std::string Name;
  RendererFactory Factory;
  int Priority;
};

std::unique_ptr<Renderer> MakeCpuRenderer(std::string*)
{
  return CreateCpuRenderer();
}

/// The registry, with "cpu" in it from the start (a function-local static: no initialisation order
/// problem with backends that register from their own static initialisers).
std::vector<Entry>& Registry(std::unique_lock<std::mutex>& lock)
{
  static std::mutex mutex;
  static std::vector<Entry> entries{ { "cpu", &MakeCpuRenderer, 0 } };
  lock = std::unique_lock<std::mutex>(mutex);
  return entries;
}

BackendCheck CheckBackendOnce(const std::string& name, Renderer* renderer); // below, with CheckBackend

/// The self-checks run so far, by backend (CheckBackend), under their own lock: a check runs a
/// backend's factory, which may register.
std::map<std::string, BackendCheck>& Checks(std::unique_lock<std::mutex>& lock)
{
  static std::mutex mutex;
  static std::map<std::string, BackendCheck> checks;
  lock = std::unique_lock<std::mutex>(mutex);
  return checks;
}

/// What each backend runs on (SetBackendDescription; guarded by the registry's lock).
std::map<std::string, std::string>& Descriptions()
{
  static std::map<std::string, std::string> descriptions;
  return descriptions;
}

/// Backends built but not usable here, and why (guarded by the registry's lock).
std::map<std::string, std::string>& Unavailable()
{
  static std::map<std::string, std::string> reasons;
  return reasons;
}

/**
 * Loads the run-time backend modules once, before the registry is first read. Their registration
 * calls RegisterBackend, so this runs outside the registry's lock and RegisterBackend never calls it.
 */
void LoadBackendModules()
{
#if defined(BIGUS_CUDA_BACKEND_LIBRARY)
  static std::once_flag once;
  std::call_once(once, [] {
    const std::string library = BIGUS_CUDA_BACKEND_LIBRARY;
    std::string folder;
    Dl_info self;
    if (dladdr(reinterpret_cast<void*>(&LoadBackendModules), &self) && self.dli_fname)
    {
      folder = self.dli_fname;
      folder = folder.substr(0, folder.find_last_of('/') + 1);
    }
    // The library beside this one first (build and install trees), then the loader's search path; the
    // first failure is the telling one (a missing libcudart, say).
    std::string why;
    void* handle = nullptr;
    for (const std::string& path : { folder.empty() ? std::string() : folder + library, library })
    {
      if (!path.empty() && !(handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL)) && why.empty())
      {
        const char* text = dlerror();
        why = text ? text : "unknown error";
      }
      if (handle)
      {
        break;
      }
    }
    using Registration = void (*)();
    const Registration reg =
      handle ? reinterpret_cast<Registration>(dlsym(handle, "bigusCudaRegisterBackend")) : nullptr;
    if (reg)
    {
      reg();
    }
    else
    {
      RegisterUnavailableBackend("cuda", "cannot load " + library + ": " + (handle ? "no registration function" : why));
    }
  });
#endif
}
}

void RegisterBackend(const std::string& name, RendererFactory factory, int priority)
{
  std::unique_lock<std::mutex> lock;
  std::vector<Entry>& entries = Registry(lock);
  Unavailable().erase(name);
  entries.erase(
    std::remove_if(entries.begin(), entries.end(), [&](const Entry& e) { return e.Name == name; }), entries.end());
  entries.push_back({ name, factory, priority });
  std::stable_sort(
    entries.begin(), entries.end(), [](const Entry& a, const Entry& b) { return a.Priority > b.Priority; });
  lock.unlock();
  std::unique_lock<std::mutex> checksLock;
  Checks(checksLock).erase(name); // a replaced backend proves itself again
}

void RegisterUnavailableBackend(const std::string& name, const std::string& why)
{
  std::unique_lock<std::mutex> lock;
  Registry(lock);
  Unavailable()[name] = why;
}

void SetBackendDescription(const std::string& name, const std::string& description)
{
  std::unique_lock<std::mutex> lock;
  Registry(lock);
  Descriptions()[name] = description;
}

std::string BackendDescription(const std::string& name)
{
  LoadBackendModules();
  std::unique_lock<std::mutex> lock;
  Registry(lock);
  const auto found = Descriptions().find(name);
  return found == Descriptions().end() ? std::string() : found->second;
}

std::vector<std::string> AvailableBackends()
{
  LoadBackendModules();
  std::unique_lock<std::mutex> lock;
  std::vector<std::string> names;
  for (const Entry& e : Registry(lock))
  {
    names.push_back(e.Name);
  }
  return names;
}

std::vector<std::pair<std::string, std::string>> UnavailableBackends()
{
  LoadBackendModules();
  std::unique_lock<std::mutex> lock;
  Registry(lock);
  return { Unavailable().begin(), Unavailable().end() };
}

std::string ResolveBackend(const std::string& name, std::string* error)
{
  const std::vector<std::string> names = AvailableBackends();
  if (name.empty() || name == "auto")
  {
    // The first backend in priority order that passes its self-check ("cpu" always does).
    for (const std::string& n : names)
    {
      if (n == "cpu" || CheckBackend(n).Passed)
      {
        return n;
      }
    }
  }
  if (std::find(names.begin(), names.end(), name) != names.end())
  {
    return name;
  }
  if (error)
  {
    std::string list;
    for (const std::string& n : names)
    {
      list += (list.empty() ? "" : ", ") + n;
    }
    std::string why;
    {
      std::unique_lock<std::mutex> lock;
      Registry(lock);
      const auto found = Unavailable().find(name);
      why = found == Unavailable().end() ? std::string() : found->second;
    }
    *error = "backend '" + name + "' " + (why.empty() ? "is not available in this build" : "cannot run here: " + why) +
      "; available: auto, " + list;
  }
  return std::string();
}

std::unique_ptr<Renderer> CreateRenderer(const std::string& name, std::string* error, std::string* notice)
{
  // "auto" tries every backend in priority order, each made once and checked on that instance (not
  // through ResolveBackend, whose check would make a second one); an explicit name only itself.
  const bool automatic = name.empty() || name == "auto";
  if (!automatic && ResolveBackend(name, error).empty())
  {
    return nullptr;
  }
  LoadBackendModules();
  std::vector<Entry> candidates;
  {
    std::unique_lock<std::mutex> lock;
    for (const Entry& e : Registry(lock))
    {
      if (automatic || e.Name == name)
      {
        candidates.push_back(e);
      }
    }
  }
  std::string skipped;
  for (const Entry& e : candidates)
  {
    std::string why;
    std::unique_ptr<Renderer> renderer = e.Factory(&why);
    if (!renderer)
    {
      skipped += (skipped.empty() ? "" : "; ") + ("backend '" + e.Name + "' cannot be used: " + why);
      continue;
    }
    // A backend other than the reference proves itself first: "auto" passes over one that fails, an
    // explicit name runs it with the warning.
    std::string warning;
    if (e.Name != "cpu")
    {
      const BackendCheck check = CheckBackendOnce(e.Name, renderer.get());
      if (!check.Passed)
      {
        warning = "backend '" + e.Name + "' failed its self-check against the CPU renderer: " + check.Detail;
        if (automatic)
        {
          skipped += (skipped.empty() ? "" : "; ") + warning;
          continue;
        }
      }
    }
    if (notice && !(skipped.empty() && warning.empty()))
    {
      *notice = automatic ? skipped + "; using " + e.Name : warning;
    }
    return renderer;
  }
  if (error)
  {
    *error = skipped;
  }
  return nullptr;
}

namespace
{
/**
 * The self-check of backend @p name, run once (then cached) on @p renderer when given (an instance the
 * caller just made, so that checking makes no second one) or on one its factory makes.
 */
BackendCheck CheckBackendOnce(const std::string& name, Renderer* renderer)
{
  LoadBackendModules(); // they register (taking the checks' lock) before that lock is held here
  std::unique_lock<std::mutex> lock;
  std::map<std::string, BackendCheck>& checks = Checks(lock);
  const auto found = checks.find(name);
  if (found != checks.end())
  {
    return found->second;
  }
  BackendCheck check;
  check.Backend = name;
  if (name == "cpu")
  {
    check.Passed = true;
    check.Detail = "the reference renderer";
  }
  else if (renderer)
  {
    check = CheckRenderer(*renderer);
    check.Backend = name;
  }
  else
  {
    RendererFactory factory = nullptr;
    std::string error;
    if (!ResolveBackend(name, &error).empty())
    {
      std::unique_lock<std::mutex> registryLock;
      for (const Entry& e : Registry(registryLock))
      {
        factory = e.Name == name ? e.Factory : factory;
      }
    }
    std::unique_ptr<Renderer> renderer = factory ? factory(&error) : nullptr;
    if (renderer)
    {
      check = CheckRenderer(*renderer);
      check.Backend = name;
    }
    else
    {
      check.Detail = error;
    }
  }
  checks[name] = check;
  return check;
}
}

BackendCheck CheckBackend(const std::string& name)
{
  return CheckBackendOnce(name, nullptr);
}

} // namespace bigus

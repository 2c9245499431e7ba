/**
 * @file bigusBackend.h
 * @brief The one place a rendering backend is chosen (DESIGN section 5): a registry of renderer
 *        factories by name. Every filter, the trainer and every command create their renderer here.
 *
 * Names: "cpu" (always registered, bigus::CreateCpuRenderer) and any backend that registers itself.
 * BIGUS::Cuda is a run-time module: where it was built, the registry loads its library (from the
 * folder of this library, then the loader's search path) on first use, and it registers "cuda" when
 * a usable device exists, or else records why not. So every program, Python and ParaView included,
 * gets the GPU without linking to it. "auto" is the available backend of highest priority, so "cuda"
 * wherever it registered and "cpu" otherwise.
 */
#ifndef bigusBackend_h
#define bigusBackend_h

#include "bigusRenderer.h"
#include "bigusRenderingModule.h" // For export macro

#include <memory>
#include <string>
#include <utility>
#include <vector>

namespace bigus
{

/// Makes a renderer; null with @p error set when the backend cannot run here (no device, ...).
using RendererFactory = std::unique_ptr<Renderer> (*)(std::string* error);

/**
 * Registers (or replaces) backend @p name. @p priority orders "auto": the highest wins ("cpu" has 0).
 * Called once by a backend module when it is loaded.
 */
BIGUSRENDERING_EXPORT void RegisterBackend(const std::string& name, RendererFactory factory, int priority);

/**
 * Records that backend @p name exists in this build but cannot run here, and @p why ("no CUDA device
 * is visible"); ResolveBackend's error for that name says so. Registering the name later clears it.
 */
BIGUSRENDERING_EXPORT void RegisterUnavailableBackend(const std::string& name, const std::string& why);

/**
 * Records what backend @p name runs on, for reports (`bigus info --backends`, `bigus benchmark`): for "cuda" the
 * device, its compute capability and memory, the driver and the CUDA runtime. Called by a backend module when it
 * registers.
 */
BIGUSRENDERING_EXPORT void SetBackendDescription(const std::string& name, const std::string& description);

/// What backend @p name runs on (SetBackendDescription); empty where nothing was recorded (the CPU backend: the
/// processor is the machine's).
BIGUSRENDERING_EXPORT std::string BackendDescription(const std::string& name);

/// The registered backend names, highest priority first ("cpu" is always among them).
BIGUSRENDERING_EXPORT std::vector<std::string> AvailableBackends();

/// The backends built but unable to run here, each with why (RegisterUnavailableBackend), by name.
BIGUSRENDERING_EXPORT std::vector<std::pair<std::string, std::string>> UnavailableBackends();

/**
 * The backend that @p name selects: @p name itself when it is registered, the highest-priority one
 * for "auto" (or an empty name). Returns an empty string with @p error ("backend 'cuda' is not
 * available in this build; available: auto, cpu", or for a built backend that cannot run here "backend
 * 'cuda' cannot run here: no CUDA device is visible; available: auto, cpu") for an unknown, unbuilt or
 * unusable backend.
 */
BIGUSRENDERING_EXPORT std::string ResolveBackend(const std::string& name, std::string* error);

/**
 * A renderer of backend @p name ("auto", "cpu", "cuda", ...); its GetName() says which one. An
 * explicit name gives that backend or null with @p error naming it and why it cannot be used (no
 * silent fallback). "auto" tries the backends in priority order; when one is skipped (a CUDA build
 * on a machine without a device) @p notice, if given, says which and why, for the caller to show.
 */
BIGUSRENDERING_EXPORT std::unique_ptr<Renderer> CreateRenderer(
  const std::string& name, std::string* error, std::string* notice = nullptr);

} // namespace bigus

#endif

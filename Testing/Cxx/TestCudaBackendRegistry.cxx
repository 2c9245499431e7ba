// The backend registry in a build with the CUDA backend: "cuda" is offered exactly where a usable
// device exists. Without one, asking for it says why, and "auto" stays on the CPU without a notice
// (the filters would print it as a warning on every update). Runs on every machine with nvcc.
#include "bigusBackend.h"
#include "bigusCudaDevice.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <string>

using namespace bigus;

TEST(CudaBackendRegistry, CudaIsOfferedExactlyWhereADeviceIsUsable)
{
  cuda::DeviceInfo info;
  std::string why;
  const bool usable = cuda::QueryDevice(info, why);
  const std::vector<std::string> names = AvailableBackends();
  const bool offered = std::find(names.begin(), names.end(), "cuda") != names.end();
  EXPECT_EQ(offered, usable) << (usable ? info.Name : why);
  std::string error, notice;
  std::unique_ptr<Renderer> automatic = CreateRenderer("auto", &error, &notice);
  ASSERT_TRUE(automatic) << error;
  EXPECT_STREQ(automatic->GetName(), usable ? "cuda" : "cpu");
  EXPECT_TRUE(notice.empty()) << notice;
  error.clear();
  const std::string resolved = ResolveBackend("cuda", &error);
  if (usable)
  {
    EXPECT_EQ(resolved, "cuda");
  }
  else
  {
    EXPECT_TRUE(resolved.empty());
    EXPECT_EQ(error, "backend 'cuda' cannot run here: " + why + "; available: auto, cpu");
    EXPECT_FALSE(CreateRenderer("cuda", &error)) << "no silent fallback for an explicit name";
  }
}

TEST(CudaBackendRegistry, AnUnknownBackendIsStillNotInTheBuild)
{
  std::string error;
  EXPECT_TRUE(ResolveBackend("no-such-backend", &error).empty());
  EXPECT_EQ(error.find("backend 'no-such-backend' is not available in this build; available: auto, "), 0u) << error;
}

# A downstream project against the installed package (Examples/Downstream), run by ctest:
# installs the build into a fresh prefix, configures and builds the project there with
# find_package(BIGUS), runs its TrainAndReslice on the N-wire fixture and checks that it writes the
# same PNG, byte for byte, as the same source built inside the BIGUS build (training on the CPU is
# deterministic whatever the thread count, DESIGN section 5).
#
#   cmake -DBUILD_DIR=... -DSOURCE_DIR=... -DWORK_DIR=... -DSWEEP=... -DCALIBRATION=... -DIN_TREE=... -P Downstream.cmake
foreach (var BUILD_DIR SOURCE_DIR WORK_DIR SWEEP CALIBRATION IN_TREE)
  if (NOT DEFINED ${var})
    message(FATAL_ERROR "Downstream.cmake: -D${var}=... is required")
  endif ()
endforeach ()

function (run)
  execute_process(COMMAND ${ARGN} RESULT_VARIABLE code OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if (NOT code EQUAL 0)
    string(REPLACE ";" " " command "${ARGN}")
    message(FATAL_ERROR "${command} failed (${code}):\n${out}\n${err}")
  endif ()
endfunction ()

file(REMOVE_RECURSE "${WORK_DIR}")
set(prefix "${WORK_DIR}/prefix")
run("${CMAKE_COMMAND}" --install "${BUILD_DIR}" --prefix "${prefix}")
foreach (file BIGUSConfig.cmake BIGUSConfigVersion.cmake BIGUS-targets.cmake)
  if (NOT EXISTS "${prefix}/lib/cmake/bigus/${file}")
    message(FATAL_ERROR "the install has no lib/cmake/bigus/${file}")
  endif ()
endforeach ()
run("${CMAKE_COMMAND}" -S "${SOURCE_DIR}/Examples/Downstream" -B "${WORK_DIR}/build" -G Ninja
  -DCMAKE_BUILD_TYPE=Release "-DCMAKE_PREFIX_PATH=${prefix}")
run("${CMAKE_COMMAND}" --build "${WORK_DIR}/build")
run("${WORK_DIR}/build/TrainAndReslice" "${SWEEP}" "${CALIBRATION}" "${WORK_DIR}/downstream.png" 20)
run("${IN_TREE}" "${SWEEP}" "${CALIBRATION}" "${WORK_DIR}/in-tree.png" 20)
file(SHA256 "${WORK_DIR}/downstream.png" downstream)
file(SHA256 "${WORK_DIR}/in-tree.png" inTree)
file(SIZE "${WORK_DIR}/downstream.png" size)
if (NOT downstream STREQUAL inTree OR size LESS 100)
  message(FATAL_ERROR "the downstream build's slice (${size} bytes) differs from the in-tree build's")
endif ()
message(STATUS "downstream project: built against ${prefix}, its slice matches the in-tree build's (${size} bytes)")

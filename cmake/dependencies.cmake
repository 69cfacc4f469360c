# Every third-party dependency of heightcast, found here and nowhere else, each with the oldest version we build
# against (all from Debian 12 / Ubuntu 22.04+ packages: scripts/deps.sh installs them). Which folder may use which
# is a rule of the layout (CONTRIBUTING.md); a folder links its dependencies PRIVATE, so none leaks upward:
#   core/      Threads; core/exr/ (hc_exr, the one OpenEXR writer): OpenEXR; core/ranks/ (hc_ranks): MPI (HC_WITH_MPI)
#   grid/      -
#   ingest/    GDAL (and its PROJ), GeographicLib, fmt
#   influence/ -
#   export/    GDAL, OpenVDB (HC_WITH_VDB); .exr through hc_exr
#   render/    GLM (PUBLIC: the camera math's vocabulary), libpng, nlohmann-json; .exr through hc_exr; render/gl/: OpenGL + EGL, glslangValidator (HC_WITH_GL)
#   apps/      fmt, nlohmann-json (bookmarks, hc-info); hc-info: PROJ; hc-view: GLFW + OpenGL (HC_WITH_GL)
#   tests/     GoogleTest, and any library above to read files back; bench/: fmt, nlohmann-json
find_package(Threads REQUIRED)
find_package(GDAL 3.0 REQUIRED)
find_package(OpenEXR 3 CONFIG REQUIRED)
# PROJ's C API (GDAL's own PROJ; Debian: libproj-dev). Its config file accepts only a request for its own major
# version, so the oldest we build against (8, Ubuntu 22.04) is checked by hand.
find_package(PROJ CONFIG REQUIRED)
if(PROJ_VERSION VERSION_LESS 8)
  message(FATAL_ERROR "PROJ ${PROJ_VERSION} found; heightcast needs 8 or newer")
endif()
find_package(PNG 1.6 REQUIRED)
find_package(glm 0.9.9 CONFIG REQUIRED)
find_package(nlohmann_json 3.10 CONFIG REQUIRED)
find_package(fmt 8 CONFIG REQUIRED)

# GeographicLib's Debian package ships a find module without a version or a target: find it by hand, check
# the version its Config.h declares, and give it a target like the others.
find_library(GEOGRAPHICLIB_LIBRARY GeographicLib REQUIRED)
find_path(GEOGRAPHICLIB_INCLUDE_DIR GeographicLib/Config.h REQUIRED)
file(STRINGS ${GEOGRAPHICLIB_INCLUDE_DIR}/GeographicLib/Config.h hc_geographiclib_version
     REGEX "#define GEOGRAPHICLIB_VERSION_STRING")
string(REGEX MATCH "[0-9]+\\.[0-9]+(\\.[0-9]+)?" hc_geographiclib_version "${hc_geographiclib_version}")
if(hc_geographiclib_version VERSION_LESS 1.49)
  message(FATAL_ERROR "GeographicLib ${hc_geographiclib_version} found; heightcast needs 1.49 or newer")
endif()
add_library(hc::GeographicLib INTERFACE IMPORTED)
set_target_properties(hc::GeographicLib PROPERTIES INTERFACE_LINK_LIBRARIES ${GEOGRAPHICLIB_LIBRARY}
                      INTERFACE_INCLUDE_DIRECTORIES ${GEOGRAPHICLIB_INCLUDE_DIR})

if(HC_WITH_VDB)
  # OpenVDB ships a find module, not a config file (Debian: libopenvdb-dev).
  list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB /usr/lib/cmake/OpenVDB /usr/local/lib/cmake/OpenVDB)
  find_package(OpenVDB 9 REQUIRED)
endif()

if(HC_WITH_MPI)
  # core/ranks/ (hc-ingest and hc-influence under mpirun; Debian: libopenmpi-dev openmpi-bin). Optional: without it
  # the build goes on as one process (a normal variable shadows the option for this configure run).
  find_package(MPI 3.0 COMPONENTS CXX)
  if(NOT MPI_CXX_FOUND)
    message(WARNING "HC_WITH_MPI: no MPI found (Debian: libopenmpi-dev): hc-ingest and hc-influence run as one process")
    set(HC_WITH_MPI OFF)
  endif()
endif()

if(HC_WITH_GL)
  # render/gl/: libglvnd's OpenGL and EGL (headless through the EGL surfaceless platform; libOpenGL exports the core
  # functions, so no loader), and glslangValidator to check the compute shaders at build time (Debian: libegl-dev
  # libgl-dev glslang-tools; Mesa's libgl1-mesa-dri provides llvmpipe where there is no GPU). hc-view: GLFW (X11).
  # CMake's OpenGL module has no version: the OpenGL 4.3 core context the backend needs is asked for at run time,
  # and a driver without it is refused with the reason (render/gl/src/context.cpp).
  find_package(OpenGL REQUIRED COMPONENTS OpenGL EGL)
  find_program(HC_GLSLANG_VALIDATOR glslangValidator REQUIRED)
  find_package(glfw3 3.3 REQUIRED)
endif()

if(HC_BUILD_TESTS)
  find_package(GTest 1.10 REQUIRED)
  # The CLI tests' driver (tests/cli/expect.sh), and Xvfb for hc-view's window tests (optional: without it they are
  # left out with a warning).
  find_program(HC_BASH bash REQUIRED)
  find_program(HC_XVFB_RUN xvfb-run)
  # ffmpeg (Debian package ffmpeg) for hc-render --video: optional at run time; the CLI tests check the video where it
  # is installed and the refusal where it is not. gdal_create (gdal-bin) makes the water rasters of the series tests.
  find_program(HC_FFMPEG ffmpeg)
  find_program(HC_GDAL_CREATE gdal_create)
  # mpirun (openmpi-bin) for the MPI tests (tests/cli/mpi.cmake): byte-identical outputs from 1, 2 and 3 ranks where the
  # build has MPI, the refusal of several ranks where it has not.
  find_program(HC_MPIEXEC NAMES mpirun mpiexec)
endif()

# Every third-party dependency, found once, with the version we need (all from Debian packages).
# Which folder may use which is a rule of the layout (CONTRIBUTING.md): GDAL and GeographicLib in
# ingest/ and export/, OpenEXR and OpenVDB in export/ only; tests may read files back with any.
find_package(Threads REQUIRED)
find_package(GDAL 3.0 REQUIRED)
find_library(GEOGRAPHICLIB_LIBRARY GeographicLib REQUIRED)
find_path(GEOGRAPHICLIB_INCLUDE_DIR GeographicLib/TransverseMercator.hpp REQUIRED)
find_package(OpenEXR 3 CONFIG REQUIRED)
# OpenVDB ships a find module, not a config file (Debian: libopenvdb-dev).
list(APPEND CMAKE_MODULE_PATH /usr/lib/x86_64-linux-gnu/cmake/OpenVDB /usr/lib/cmake/OpenVDB /usr/local/lib/cmake/OpenVDB)
find_package(OpenVDB 9 REQUIRED)
if(HC_BUILD_TESTS)
  find_package(GTest 1.10 REQUIRED)
endif()
# hc-view's window (GLFW, X11) and OpenGL through glvnd: libOpenGL exports the core functions, so no loader.
find_package(glfw3 3.3 REQUIRED)
find_package(OpenGL REQUIRED COMPONENTS OpenGL)
# render/'s GL backend: libglvnd's OpenGL and EGL (headless through the EGL surfaceless platform), and
# glslangValidator to check the compute shaders at build time (Debian: libegl-dev libgl-dev
# glslang-tools; Mesa's libgl1-mesa-dri provides llvmpipe where there is no GPU).
find_package(OpenGL REQUIRED COMPONENTS OpenGL EGL)
find_program(HC_GLSLANG_VALIDATOR glslangValidator REQUIRED)

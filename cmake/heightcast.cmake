# HC_SANITIZE: ASan + UBSan on everything built here (libraries, apps, tests), so a finding anywhere stops the
# run; -fno-sanitize-recover makes UB fatal instead of a line in a log nobody reads.
if(HC_SANITIZE)
  if(NOT CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    message(FATAL_ERROR "HC_SANITIZE needs GCC or Clang")
  endif()
  add_compile_options(-fsanitize=address,undefined -fno-sanitize-recover=undefined -fno-omit-frame-pointer)
  add_link_options(-fsanitize=address,undefined -fno-sanitize-recover=undefined)
endif()

# One function gives every heightcast target the same flags, so no folder drifts.
function(hc_target_defaults target)
  target_compile_features(${target} PUBLIC cxx_std_20)
  if(CMAKE_CXX_COMPILER_ID MATCHES "GNU|Clang")
    target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wconversion
                                             -Wno-sign-conversion -Wnon-virtual-dtor)
    if(HC_WERROR)
      target_compile_options(${target} PRIVATE -Werror)
    endif()
    if(HC_NATIVE)
      target_compile_options(${target} PRIVATE -march=native)
    endif()
  endif()
endfunction()

# hc_add_library(NAME SOURCES...): a folder's library with its public headers in include/.
function(hc_add_library name)
  add_library(${name} STATIC ${ARGN})  # static whatever a find module sets BUILD_SHARED_LIBS to
  target_include_directories(${name} PUBLIC ${CMAKE_CURRENT_SOURCE_DIR}/include)
  hc_target_defaults(${name})
endfunction()

# hc_add_app(NAME SOURCES... LIBS ...): a thin command-line main.
function(hc_add_app name)
  cmake_parse_arguments(A "" "" "SOURCES;LIBS" ${ARGN})
  add_executable(${name} ${A_SOURCES})
  target_link_libraries(${name} PRIVATE ${A_LIBS})
  hc_target_defaults(${name})
endfunction()

# Link Ceres as the shared library, not the static one Debian's CMake package names.
#
# Debian's libceres.a is compiled for SSE, where Eigen allocates heap arrays with plain
# malloc; tactfunc compiles with -march=native, where (AVX-512) Eigen allocates them
# 64-byte aligned by hand, with malloc's own pointer stored before the data. Eigen's
# allocation code is inline: linked statically, the program holds both copies under the
# same symbol names (Eigen::internal::aligned_malloc, PlainObjectBase<>::resize, ...)
# and the linker keeps one of each, so a buffer allocated by Ceres' copy can be freed by
# tactfunc's, and the program crashes in free() depending on what the compiler inlined.
# libceres.so exports no Eigen symbol: its copies stay private to it. docs/BUILD.md.
# Used by the build and by the installed tactfuncConfig.cmake.
get_target_property(_tactfunc_ceres_location Ceres::ceres IMPORTED_LOCATION_RELEASE)
if(_tactfunc_ceres_location MATCHES "\\.a$")
  string(REGEX REPLACE "\\.a$" ".so" _tactfunc_ceres_shared "${_tactfunc_ceres_location}")
  if(NOT EXISTS "${_tactfunc_ceres_shared}")
    message(FATAL_ERROR "tactfunc links Ceres as a shared library, but only "
      "${_tactfunc_ceres_location} was found (expected ${_tactfunc_ceres_shared}; on "
      "Debian it comes with libceres-dev). A static Ceres mixes two Eigen allocators "
      "in one program (see cmake/TactfuncSharedCeres.cmake).")
  endif()
  set_target_properties(Ceres::ceres PROPERTIES
    IMPORTED_LOCATION_RELEASE "${_tactfunc_ceres_shared}")
endif()
unset(_tactfunc_ceres_location)
unset(_tactfunc_ceres_shared)

# `cmake --install` exports every library (tactfunc::models, tactfunc::samplers, the
# estimation/ concepts and the tactfunc::estimation umbrella) so that a consumer's
# find_package(tactfunc) works (tests/install checks it).
include(CMakePackageConfigHelpers)
set(TACTFUNC_CMAKE_DIR ${CMAKE_INSTALL_LIBDIR}/cmake/tactfunc)
install(TARGETS tactfunc_build_flags tactfunc_models tactfunc_samplers tactfunc_data
                tactfunc_knn tactfunc_pose tactfunc_fitting tactfunc_training
                tactfunc_functaset tactfunc_encoding tactfunc_posterior tactfunc_evaluation
                tactfunc_synthesis tactfunc_estimation
        EXPORT tactfuncTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/tactfunc)
foreach(module models estimation samplers)
  install(DIRECTORY ${PROJECT_SOURCE_DIR}/${module}
          DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/tactfunc
          FILES_MATCHING PATTERN "*.h" PATTERN "internal" EXCLUDE PATTERN "pretrained" EXCLUDE)
endforeach()
install(EXPORT tactfuncTargets NAMESPACE tactfunc:: DESTINATION ${TACTFUNC_CMAKE_DIR})
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/tactfuncConfig.cmake.in
  ${PROJECT_BINARY_DIR}/tactfuncConfig.cmake INSTALL_DESTINATION ${TACTFUNC_CMAKE_DIR})
write_basic_package_version_file(${PROJECT_BINARY_DIR}/tactfuncConfigVersion.cmake
  COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/tactfuncConfig.cmake
              ${PROJECT_BINARY_DIR}/tactfuncConfigVersion.cmake
              ${PROJECT_SOURCE_DIR}/cmake/TactfuncSharedCeres.cmake
        DESTINATION ${TACTFUNC_CMAKE_DIR})

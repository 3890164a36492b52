# cmake --install: the libraries, their headers and a CMake package, so that an outside project
# can find_package(Specula) and link specula::engine / specula::systems (and specula::present
# where built).
include(CMakePackageConfigHelpers)

set(specula_installed_libraries specula_engine specula_systems)
if(TARGET specula_present)
  list(APPEND specula_installed_libraries specula_present)
endif()
install(TARGETS ${specula_installed_libraries} EXPORT SpeculaTargets
        ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
        LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
        INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(DIRECTORY ${PROJECT_SOURCE_DIR}/engine/ DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/specula
        FILES_MATCHING PATTERN "*.h")
install(DIRECTORY ${PROJECT_SOURCE_DIR}/systems DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/specula
        FILES_MATCHING PATTERN "*.h")
install(DIRECTORY ${PROJECT_SOURCE_DIR}/shaders/shared DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/specula
        FILES_MATCHING PATTERN "*.h")
install(EXPORT SpeculaTargets NAMESPACE specula:: FILE SpeculaTargets.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/Specula)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/SpeculaConfig.cmake.in
  ${PROJECT_BINARY_DIR}/SpeculaConfig.cmake INSTALL_DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/Specula)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/SpeculaConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES ${PROJECT_BINARY_DIR}/SpeculaConfig.cmake ${PROJECT_BINARY_DIR}/SpeculaConfigVersion.cmake
        DESTINATION ${CMAKE_INSTALL_LIBDIR}/cmake/Specula)
if(SPECULA_BUILD_EDITOR)
  install(TARGETS specula RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
endif()

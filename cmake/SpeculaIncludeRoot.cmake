# Every project header is included as "specula/<folder>/<file>.h", in the tree and once installed,
# so an outside program writes <specula/scene/scene.h> and never collides with other libraries'
# "scene/" or "image/" folders. In the build tree the prefix is a folder of links to the source
# folders (${PROJECT_BINARY_DIR}/include/specula/<folder> -> the source); installed, the headers
# are copied under <prefix>/include/specula/ (cmake/SpeculaInstall.cmake).
set(SPECULA_INCLUDE_ROOT ${PROJECT_BINARY_DIR}/include)
set(SPECULA_ENGINE_HEADER_DIRS accel cache core ecs geometry gpu image present render scene trace)
file(MAKE_DIRECTORY ${SPECULA_INCLUDE_ROOT}/specula)
foreach(dir ${SPECULA_ENGINE_HEADER_DIRS})
  if(IS_DIRECTORY ${PROJECT_SOURCE_DIR}/engine/${dir})
    file(CREATE_LINK ${PROJECT_SOURCE_DIR}/engine/${dir} ${SPECULA_INCLUDE_ROOT}/specula/${dir} SYMBOLIC)
  endif()
endforeach()
file(CREATE_LINK ${PROJECT_SOURCE_DIR}/systems ${SPECULA_INCLUDE_ROOT}/specula/systems SYMBOLIC)
# Structs shared by C++ and GLSL: "specula/shared/<file>.h".
file(CREATE_LINK ${PROJECT_SOURCE_DIR}/shaders/shared ${SPECULA_INCLUDE_ROOT}/specula/shared SYMBOLIC)

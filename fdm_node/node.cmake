# Scene keys -> fdm_core parameters, shared with other continuum nodes on fdm_core's mesh.
add_library(fdm_scene STATIC ${CMAKE_CURRENT_SOURCE_DIR}/scene_params.cpp)
target_include_directories(fdm_scene PUBLIC ${PROJECT_SOURCE_DIR})
target_link_libraries(fdm_scene PUBLIC fdm_core demfdm_config)
add_executable(fdm_node ${CMAKE_CURRENT_SOURCE_DIR}/main.cpp)
target_link_libraries(fdm_node PRIVATE fdm_scene fdm_core demfdm_node demfdm_io OpenMP::OpenMP_CXX)

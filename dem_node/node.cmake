add_executable(dem_node ${CMAKE_CURRENT_SOURCE_DIR}/main.cpp)
target_link_libraries(dem_node PRIVATE dem_core dem_dist dem_scene demfdm_node demfdm_io OpenMP::OpenMP_CXX)

add_executable(fdm_node ${CMAKE_CURRENT_SOURCE_DIR}/main.cpp)
target_link_libraries(fdm_node PRIVATE fdm_core demfdm_node demfdm_io OpenMP::OpenMP_CXX)

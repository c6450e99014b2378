# continuum_base: what every continuum node adapter shares (fdm_node, fem_node): scene keys of
# the mesh and the materials (scene_params), and the NodeBase participant (continuum_base:
# interface plumbing, balance check, result files, model clock). Built on fdm_mesh only, so a
# solver that is not the FDM links no FDM code through it: of fdm_core it uses the header of the
# parameter structs, whose tables declare the material and continuum keys (header-only).
add_library(continuum_base STATIC
  ${CMAKE_CURRENT_SOURCE_DIR}/scene_params.cpp
  ${CMAKE_CURRENT_SOURCE_DIR}/continuum_base.cpp)
target_include_directories(continuum_base PUBLIC ${PROJECT_SOURCE_DIR} ${PROJECT_SOURCE_DIR}/fdm_node/core/include)
target_link_libraries(continuum_base PUBLIC fdm_mesh demfdm_config demfdm_node demfdm_io)
add_executable(fdm_node ${CMAKE_CURRENT_SOURCE_DIR}/main.cpp)
target_link_libraries(fdm_node PRIVATE continuum_base fdm_core OpenMP::OpenMP_CXX)

# Mechanics: step and 2-s trial times of canonical scenes (figures in bench/README.md).
arena_bench(mechanics_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/mechanics_bench.cpp LIBS arena::mechanics)
# Whole runs of scene files, timed (also builds against an older commit's
# library: bench/README.md, "Steered slip and the defaults' cost").
arena_bench(scene_timing SOURCES ${CMAKE_CURRENT_LIST_DIR}/scene_timing.cpp LIBS arena::mechanics)
target_compile_definitions(scene_timing PRIVATE ARENA_SCENE_TIMING_CONE)

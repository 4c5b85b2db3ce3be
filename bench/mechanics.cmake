# Mechanics: step and 2-s trial times of canonical scenes (figures in bench/README.md).
arena_bench(mechanics_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/mechanics_bench.cpp LIBS arena::mechanics)

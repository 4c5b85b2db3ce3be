# Cost of a sensitivity report per scene (issue 18): model runs and wall time,
# on 1 and 2 threads (bench/README.md, "Sensitivity").
arena_bench(sensitivity_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/sensitivity_bench.cpp
            LIBS arena::assessment arena::mechanics)

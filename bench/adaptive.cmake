# Adaptive boundary sampling vs the grid on the same simulated cells
# (bench/README.md, "Adaptive boundary sampling"); a study program, not a timer.
arena_bench(boundary_study SOURCES ${CMAKE_CURRENT_LIST_DIR}/boundary_study.cpp
            LIBS arena::orchestrator arena::executors arena::mechanics)

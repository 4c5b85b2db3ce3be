# Speed/accuracy study (issue 7): convergence of the model against the closed
# forms of the mechanics validation tests (bench/README.md, "Convergence").
arena_bench(convergence_study SOURCES ${CMAKE_CURRENT_LIST_DIR}/convergence_study.cpp LIBS arena::mechanics)
target_include_directories(convergence_study PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)
# Residuals and solve success per case of the mechanics extremes suite ("Extremes").
arena_bench(extremes_table SOURCES ${CMAKE_CURRENT_LIST_DIR}/extremes_table.cpp LIBS arena::mechanics)
target_include_directories(extremes_table PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)

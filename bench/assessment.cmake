# Evaluation throughput (issue 14): EvaluateCampaign on 1,000 trials x 16
# settings (bench/README.md, "Evaluation throughput").
arena_bench(evaluation_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/evaluation_bench.cpp
            LIBS arena::assessment arena::db nlohmann_json::nlohmann_json)
target_compile_definitions(evaluation_bench PRIVATE ARENA_BINARY="$<TARGET_FILE:arena>")
add_dependencies(evaluation_bench arena)
# Stability at the extremes per predictor (bench/README.md, "Extremes per predictor").
arena_bench(predictor_extremes SOURCES ${CMAKE_CURRENT_LIST_DIR}/predictor_extremes.cpp
            LIBS arena::assessment)
target_include_directories(predictor_extremes PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)
# MuJoCo calibration runs: compiled afresh vs prepared once (bench/README.md,
# "Calibration against MuJoCo").
arena_bench(calibration_bench SOURCES ${CMAKE_CURRENT_LIST_DIR}/calibration_bench.cpp
            LIBS arena::simulators arena::mechanics)
target_include_directories(calibration_bench PRIVATE ${PROJECT_SOURCE_DIR}/tests/mechanics)

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

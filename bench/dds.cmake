# DDS: sustained ground-truth throughput and latency on loopback (bench/README.md, "DDS").
arena_bench(bench_dds SOURCES ${CMAKE_CURRENT_LIST_DIR}/dds_bench.cpp LIBS arena::schemas arena::executors)

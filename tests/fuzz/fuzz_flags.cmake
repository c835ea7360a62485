# Compiler flags for -DMACRO_FUZZ=ON, applied to every library before it is defined (included from
# the top-level CMakeLists.txt). Libraries get coverage instrumentation without libFuzzer's main;
# the targets themselves link -fsanitize=fuzzer (tests/fuzz/CMakeLists.txt).
if(NOT CMAKE_CXX_COMPILER_ID MATCHES "Clang")
  message(FATAL_ERROR "MACRO_FUZZ=ON needs clang: CC=clang CXX=clang++ cmake -DMACRO_FUZZ=ON ...")
endif()
if(MACRO_SANITIZE)
  message(FATAL_ERROR "MACRO_FUZZ=ON already enables ASan+UBSan; leave MACRO_SANITIZE off")
endif()
add_compile_options(-fsanitize=fuzzer-no-link,address,undefined -fno-sanitize-recover=undefined
                    -fno-omit-frame-pointer -g)
add_link_options(-fsanitize=address,undefined)
# -O1 -g: the usual fuzzing trade-off (fast to build, readable stacks, still quick to run).
set(CMAKE_CXX_FLAGS_RELWITHDEBINFO "-O1 -g -DNDEBUG")

# Fails when a source file reads a configuration key with Config's getters directly instead of
# declaring it as a row of its area's ConfigSchema (config_schema.hpp): a key read outside a
# schema is missing from `slamd --describe-config` and the README.
# Usage: cmake -DSOURCE_DIR=<repo> -P check_config_reads.cmake
file(GLOB_RECURSE files ${SOURCE_DIR}/src/*.cpp ${SOURCE_DIR}/src/*.hpp ${SOURCE_DIR}/include/*.hpp
     ${SOURCE_DIR}/daemon/*.cpp)
set(offenders "")
foreach(path IN LISTS files)
  if(path MATCHES "/common/config\\.cpp$" OR path MATCHES "/common/config_schema\\.hpp$")
    continue()
  endif()
  file(STRINGS ${path} lines REGEX "\\.get(Double|Int|Bool|String|Choice|DoubleList)\\(\"")
  if(lines)
    list(APPEND offenders "${path}: ${lines}")
  endif()
endforeach()
if(offenders)
  string(REPLACE ";" "\n" offenders "${offenders}")
  message(FATAL_ERROR "configuration keys read outside a ConfigSchema:\n${offenders}")
endif()

# mlfe_require_package(<Name> <apt-package> [CONFIG|MODULE])
# find_package that fails the configure step with the Debian package to install.
macro(mlfe_require_package name apt)
  find_package(${name} ${ARGN} QUIET)
  if(NOT ${name}_FOUND)
    message(FATAL_ERROR "mlfe: ${name} not found. Install the Debian package: apt-get install ${apt} "
                        "(or run scripts/install_deps.sh)")
  endif()
endmacro()

# mlfe_require_header(<var> <header> <apt-package> [find_path args...]) and
# mlfe_require_library(<var> <library> <apt-package> [find_library args...]): find_path /
# find_library that fail the configure step with the Debian package to install.
macro(mlfe_require_header var header apt)
  find_path(${var} ${header} ${ARGN})
  if(NOT ${var})
    message(FATAL_ERROR "mlfe: header ${header} not found. Install the Debian package: apt-get install ${apt}")
  endif()
endmacro()
macro(mlfe_require_library var lib apt)
  find_library(${var} ${lib} ${ARGN})
  if(NOT ${var})
    message(FATAL_ERROR "mlfe: library ${lib} not found. Install the Debian package: apt-get install ${apt}")
  endif()
endmacro()

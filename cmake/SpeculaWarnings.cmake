# specula_warnings(target): the project's warning set, applied to every target we build.
function(specula_warnings target)
  target_compile_options(${target} PRIVATE -Wall -Wextra -Wpedantic -Wshadow -Wnon-virtual-dtor
                                           -Wold-style-cast -Wcast-align -Wunused -Woverloaded-virtual
                                           -Wimplicit-fallthrough)
  # Not -Wnull-dereference: at -O2 GCC 12 reports it from inside libstdc++'s own headers
  # (streambuf, stl_construct.h) for code that is fine.
  if(SPECULA_WARNINGS_AS_ERRORS)
    target_compile_options(${target} PRIVATE -Werror)
  endif()
endfunction()

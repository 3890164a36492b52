// Mirror Run: windowed by default, or --headless replay of a recorded input file.
#include "mirror_run_game.h"

#include "../common/front_end.h"

int main(int argc, char** argv) {
  return specula::games::game_main(argc, argv, "mirror_run",
                                   [] { return std::make_unique<specula::games::MirrorRun>(); });
}

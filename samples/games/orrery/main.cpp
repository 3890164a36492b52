// Orrery: windowed by default, or --headless replay of a recorded input file.
#include "orrery_game.h"

#include "../common/front_end.h"

int main(int argc, char** argv) {
  return specula::games::game_main(argc, argv, "orrery",
                                   [] { return std::make_unique<specula::games::Orrery>(); });
}

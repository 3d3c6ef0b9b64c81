from habitsim.cli import run

run()

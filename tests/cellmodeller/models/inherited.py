# Custom per-cell numbers: plasmids shared out at division (as ex5_colonySector), a generation
# count, and a number every cell inherits unchanged.
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator

N0 = 6


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False, gamma=100, compNeighbours=True)
    sim.init(biophys, ModuleRegulator(sim, sim.moduleName), None, None)
    sim.addCell(cellType=0, pos=(0, 0, 0))
    sim.pickleSteps = 4


def init(cell):
    cell.targetVol = 3.0 + random.uniform(0.0, 0.5)
    cell.growthRate = 1.5
    cell.n_a = N0 // 2
    cell.n_b = N0 - cell.n_a
    cell.generation = 0
    cell.lineageMark = 7.25
    cell.label = "founder"


def update(cells):
    for (id, cell) in cells.items():
        cell.color = [0.1, cell.n_a / N0, cell.n_b / N0]
        cell.touching = len(cell.neighbours)
        if cell.volume > cell.targetVol:
            cell.divideFlag = True


def divide(parent, d1, d2):
    d1.targetVol = 3.0 + random.uniform(0.0, 0.5)
    d2.targetVol = 3.0 + random.uniform(0.0, 0.5)
    plasmids = [0] * parent.n_a * 2 + [1] * parent.n_b * 2
    random.shuffle(plasmids)
    d1.n_a = plasmids[:N0].count(0)
    d1.n_b = N0 - d1.n_a
    d2.n_a = plasmids[N0:].count(0)
    d2.n_b = N0 - d2.n_a
    d1.generation = d2.generation = parent.generation + 1

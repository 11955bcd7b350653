# A signalling model (as CellModeller's ex3_simpleSignal): qpcontact refuses it.
import random

from CellModeller.Biophysics.BacterialModels.CLBacterium import CLBacterium
from CellModeller.Integration.CLCrankNicIntegrator import CLCrankNicIntegrator
from CellModeller.Regulation.ModuleRegulator import ModuleRegulator
from CellModeller.Signalling.GridDiffusion import GridDiffusion


def setup(sim):
    biophys = CLBacterium(sim, jitter_z=False)
    sig = GridDiffusion(sim, 1, (64, 8, 12), (4, 4, 4), (-128, -14, -8), [10.0])
    integ = CLCrankNicIntegrator(sim, 1, 2, 2**15, sig, boundcond='reflect')
    sim.init(biophys, ModuleRegulator(sim, sim.moduleName), sig, integ)
    sim.addCell(cellType=0, pos=(0, 0, 0))


def init(cell):
    cell.targetVol = 2.5 + random.uniform(0.0, 0.5)
    cell.growthRate = 2.0
    cell.species[:] = [0]


def update(cells):
    pass

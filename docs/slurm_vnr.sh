#!/bin/bash
# Slurm batch script: train, evaluate, decode and render a multi-brick vnr model across nodes
# (docs/MPI.md). Submit with `sbatch docs/slurm_vnr.sh VOLUME.json MODEL_DIR`. Every path must be on a
# file system all nodes see (Lustre, GPFS, NFS): ranks read their bricks from VOLUME and write their
# brick files, slabs and images into MODEL_DIR's directory.
#SBATCH --job-name=vnr-bricks
#SBATCH --nodes=4
#SBATCH --ntasks-per-node=8          # ranks per node; each trains its bricks in turn
#SBATCH --cpus-per-task=8            # OpenMP threads per rank (--threads)
#SBATCH --mem-per-cpu=2G             # a 256^3 brick needs ~0.3 GiB per rank on the CPU (docs/MPI.md)
#SBATCH --time=02:00:00
#SBATCH --output=vnr-%j.out
set -euo pipefail
VOLUME=${1:?usage: sbatch slurm_vnr.sh VOLUME.json MODEL_DIR}
MODEL=${2:?usage: sbatch slurm_vnr.sh VOLUME.json MODEL_DIR}
module load openmpi 2> /dev/null || true   # site-specific; Debian: libopenmpi-dev openmpi-bin
export OMP_NUM_THREADS=$SLURM_CPUS_PER_TASK
export OMP_PROC_BIND=close OMP_PLACES=cores
# srun starts the ranks through PMI/PMIx (vnr recognises it like mpirun); with mpirun use
# `mpirun -n $SLURM_NTASKS --map-by ppr:$SLURM_NTASKS_PER_NODE:node:PE=$SLURM_CPUS_PER_TASK vnr ...`.
RUN="srun --cpu-bind=cores vnr"

# 1. Train: bricks of at most 256^3 voxels, 4 ghost voxels, 2000 steps each; a requeued or resubmitted
#    job continues where it stopped (--resume trains only the bricks not yet on disk).
$RUN train "$VOLUME" -o "$MODEL" --bricks auto --ghost 4 --steps 2000 --target-ratio 100 \
     --threads "$SLURM_CPUS_PER_TASK" --resume --report "$MODEL.train.json"
# 2. Evaluate against the volume (PSNR and max error over every voxel, summed across ranks).
$RUN eval "$MODEL" "$VOLUME" --threads "$SLURM_CPUS_PER_TASK" --report "$MODEL.eval.json"
# 3. Decode at half resolution into one NRRD file, each rank writing its slabs.
$RUN decode "$MODEL" -o "$MODEL.half.nrrd" --dims 5120,3840,768 --threads "$SLURM_CPUS_PER_TASK" --force
# 4. Render: each rank its bricks, composited sort-last on rank 0.
$RUN render "$MODEL" -o "$MODEL.png" --size 1920x1080 --orbit 30,20 --tf cool-warm --threads "$SLURM_CPUS_PER_TASK"

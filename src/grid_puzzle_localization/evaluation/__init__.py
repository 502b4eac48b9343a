"""Evaluation of localization runs, without ROS: TUM trajectories, time association, the paper's
RMSE between two modes, APE against ground truth, CPU/memory per mode under both accounting
protocols, and storage figures."""

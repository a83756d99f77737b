MODULE DrillCell
    ! an example for export --program: a drill on a plate
    PERS tooldata tDrill:=[TRUE,[[0,0,110],[0.965925826,0.000000000,0.258819045,0.000000000]],[1.2,[0,0,50],[1,0,0,0],0,0,0]];
    PERS wobjdata wPlate:=[FALSE,TRUE,"",[[350,-100,50],[0.996194698,0,0,0.087155743]],[[0,0,0],[1,0,0,0]]];
    CONST jointtarget jHome:=[[-10.0000,20.0000,10.0000,15.0000,45.0000,-30.0000],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pApproach:=[[112.2337,87.0673,218.7776],[-0.117730986,-0.092062569,0.987039304,0.058457775],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    CONST robtarget pHole1:=[[114.3019,114.1382,208.9038],[-0.137302556,-0.134846888,0.979036672,0.066719709],[-1,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]];
    VAR num nHoles:=0;
    PROC main()
        MoveAbsJ jHome\NoEOffs, v1000, z50, tool0;
        MoveJ pApproach, v500, z10, tDrill\WObj:=wPlate;
        MoveL pHole1, v50, fine, tDrill\WObj:=wPlate;
        WHILE nHoles < 2 DO
            MoveL [[117.0657,132.3705,199.4976],[-0.148696589,-0.166502198,0.972088469,0.072182766],[0,0,-1,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v50, fine, tDrill\WObj:=wPlate;
            nHoles := nHoles + 1;
        ENDWHILE
        MoveL Offs(pHole1,0,0,50), v200, z10, tDrill\WObj:=wPlate;
        SpindleOn 3000;
        MoveL [[3000,0,500],[0,0,1,0],[0,0,0,0],[9E9,9E9,9E9,9E9,9E9,9E9]], v200, fine, tDrill\WObj:=wPlate;
        MoveAbsJ [[15.0000,10.0000,20.0000,-15.0000,65.0000,70.0000],[9E9,9E9,9E9,9E9,9E9,9E9]]\NoEOffs, v1000, z50, tool0;
    ENDPROC
ENDMODULE
